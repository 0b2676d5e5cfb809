//! Serde and schemars plumbing shared by the program types: [`NonEmpty`], the schema of
//! [`Joint`] names, and a tag-first deserialiser for internally tagged enums that keeps error paths.

use std::borrow::Cow;
use std::ops::Deref;

use schemars::{json_schema, JsonSchema, Schema, SchemaGenerator};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::skeleton::Joint;

/// A list with at least one element: `and`/`or` arguments, joint lists, keyframe lists.
///
/// An empty list fails to deserialise (JSON Schema: `minItems: 1`), so an empty AND or OR cannot be
/// written down.
#[derive(Debug, Clone, PartialEq)]
pub struct NonEmpty<T>(Vec<T>);

impl<T> NonEmpty<T> {
    /// The list `[first, rest..]`.
    pub fn new(first: T, rest: Vec<T>) -> Self {
        let mut items = Vec::with_capacity(rest.len() + 1);
        items.push(first);
        items.extend(rest);
        NonEmpty(items)
    }

    /// The elements, `None` when `items` is empty.
    pub fn from_vec(items: Vec<T>) -> Option<Self> {
        if items.is_empty() {
            None
        } else {
            Some(NonEmpty(items))
        }
    }

    /// The elements as a slice (never empty).
    pub fn as_slice(&self) -> &[T] {
        &self.0
    }

    /// The elements as a vector (never empty).
    pub fn into_vec(self) -> Vec<T> {
        self.0
    }
}

impl<T> Deref for NonEmpty<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        &self.0
    }
}

impl<'a, T> IntoIterator for &'a NonEmpty<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.0.iter()
    }
}

impl<T: Serialize> Serialize for NonEmpty<T> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        self.0.serialize(serializer)
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for NonEmpty<T> {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let items = Vec::<T>::deserialize(deserializer)?;
        NonEmpty::from_vec(items).ok_or_else(|| serde::de::Error::invalid_length(0, &"at least one element"))
    }
}

impl<T: JsonSchema> JsonSchema for NonEmpty<T> {
    fn inline_schema() -> bool {
        true
    }
    fn schema_name() -> Cow<'static, str> {
        format!("NonEmpty_{}", T::schema_name()).into()
    }
    fn json_schema(generator: &mut SchemaGenerator) -> Schema {
        json_schema!({ "type": "array", "items": generator.subschema_for::<T>(), "minItems": 1 })
    }
}

/// JSON Schema of a [`Joint`] (its snake_case name); used as `#[schemars(with = "JointName")]`
/// because the skeleton module does not depend on schemars.
pub struct JointName;

impl JsonSchema for JointName {
    fn schema_name() -> Cow<'static, str> {
        "Joint".into()
    }
    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        let names: Vec<&str> = Joint::ALL.iter().map(|joint| joint.name()).collect();
        json_schema!({
            "description": "A joint of the 22-joint SMPL / HumanML3D skeleton (snake_case name).",
            "type": "string",
            "enum": names,
        })
    }
}

/// How the buffered fallback of [`tag_first_deserialize`] prefixes its message with the path
/// inside the buffered object: `at `path`: message`. [`nested_path`] takes it back apart.
pub(crate) const NESTED_PATH: (&str, &str) = ("at `", "`: ");

/// Splits the path prefixes of [`NESTED_PATH`] off `message` and appends them to `path`.
pub(crate) fn nested_path(mut path: String, mut message: &str) -> (String, String) {
    while let Some((inner, rest)) = message.strip_prefix(NESTED_PATH.0).and_then(|rest| rest.split_once(NESTED_PATH.1))
    {
        if !(path.is_empty() || inner.starts_with('[')) {
            path.push('.');
        }
        path.push_str(inner);
        message = rest;
    }
    (path, message.to_owned())
}

/// Implements `Deserialize` for an internally tagged enum whose variants each wrap one struct.
///
/// serde's derived internally tagged enums buffer the object before choosing the variant, which
/// loses the error path inside it (`constraints[2].expr` instead of `constraints[2].expr.args[1]
/// .height_m`). When the tag is the object's first key (as our serialiser and the schema's property
/// order write it) this reads the tag, then hands the rest of the same map to the variant's struct,
/// so `serde_path_to_error` follows every key. Otherwise (e.g. JSON re-serialised from a
/// `serde_json::Value`, whose keys are sorted) it buffers the object and prefixes the message with
/// the inner path ([`NESTED_PATH`]), which [`TaskProgram::from_json`] moves back into the path.
///
/// [`TaskProgram::from_json`]: super::TaskProgram::from_json
macro_rules! tag_first_deserialize {
    ($ty:ident, $tag:literal, { $($variant:ident($inner:ty) = $name:literal),+ $(,)? }) => {
        impl<'de> ::serde::Deserialize<'de> for $ty {
            fn deserialize<D: ::serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
                use ::serde::de::{Error as _, MapAccess};
                #[derive(::serde::Deserialize)]
                enum Tag { $(#[serde(rename = $name)] $variant),+ }

                fn from_buffer<E: ::serde::de::Error>(tag: Tag, rest: ::serde_json::Value) -> Result<$ty, E> {
                    fn inner<T: ::serde::de::DeserializeOwned, E: ::serde::de::Error>(
                        rest: ::serde_json::Value,
                    ) -> Result<T, E> {
                        ::serde_path_to_error::deserialize(rest).map_err(|error| {
                            let path = error.path().to_string();
                            if path == "." {
                                E::custom(error.inner())
                            } else {
                                E::custom(format!("{}{path}{}{}", $crate::program::serde_util::NESTED_PATH.0,
                                    $crate::program::serde_util::NESTED_PATH.1, error.inner()))
                            }
                        })
                    }
                    match tag { $(Tag::$variant => inner::<$inner, E>(rest).map($ty::$variant)),+ }
                }

                struct TagFirst;
                impl<'de> ::serde::de::Visitor<'de> for TagFirst {
                    type Value = $ty;
                    fn expecting(&self, f: &mut ::std::fmt::Formatter) -> ::std::fmt::Result {
                        write!(f, "an object with a `{}` field", $tag)
                    }
                    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<$ty, A::Error> {
                        let Some(first) = map.next_key::<String>()? else {
                            return Err(A::Error::missing_field($tag));
                        };
                        if first == $tag {
                            let tag: Tag = map.next_value()?;
                            let rest = ::serde::de::value::MapAccessDeserializer::new(map);
                            return match tag {
                                $(Tag::$variant => <$inner as ::serde::Deserialize>::deserialize(rest).map($ty::$variant)),+
                            };
                        }
                        let mut object = ::serde_json::Map::new();
                        object.insert(first, map.next_value::<::serde_json::Value>()?);
                        while let Some((key, value)) = map.next_entry::<String, ::serde_json::Value>()? {
                            if object.insert(key.clone(), value).is_some() {
                                return Err(A::Error::custom(format!("duplicate field `{key}`")));
                            }
                        }
                        let tag = object.remove($tag).ok_or_else(|| A::Error::missing_field($tag))?;
                        let tag = <Tag as ::serde::Deserialize>::deserialize(tag).map_err(|error| A::Error::custom(format!("{}{}{}{error}",
                            $crate::program::serde_util::NESTED_PATH.0, $tag, $crate::program::serde_util::NESTED_PATH.1)))?;
                        from_buffer(tag, ::serde_json::Value::Object(object))
                    }
                }
                deserializer.deserialize_map(TagFirst)
            }
        }
    };
}
pub(crate) use tag_first_deserialize;
