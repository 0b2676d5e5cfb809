//! The API key: sent in the `Authorization` header and nowhere else.

use std::fmt;

/// Shown wherever a key would have appeared.
pub const REDACTED: &str = "[REDACTED]";

/// A bearer token. Its `Debug` form is redacted and it has no `Display`, so it cannot reach a log
/// line or an error message by accident; [`ApiKey::scrub`] removes it from text that came back
/// from a server (some echo the request in their errors).
#[derive(Clone, PartialEq, Eq)]
pub struct ApiKey(String);

impl ApiKey {
    /// The key, `None` when blank (an empty `OPENAI_API_KEY` means no key).
    pub fn new(key: impl Into<String>) -> Option<Self> {
        let key = key.into().trim().to_owned();
        (!key.is_empty()).then_some(ApiKey(key))
    }

    /// The secret itself, for the `Authorization` header only.
    pub(crate) fn expose(&self) -> &str {
        &self.0
    }

    /// `text` with every occurrence of the key replaced by [`REDACTED`].
    pub fn scrub(&self, text: &str) -> String {
        text.replace(&self.0, REDACTED)
    }
}

impl fmt::Debug for ApiKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ApiKey({REDACTED})")
    }
}

/// `text` scrubbed of `key` when there is one.
pub fn scrub(key: Option<&ApiKey>, text: &str) -> String {
    match key {
        Some(key) => key.scrub(text),
        None => text.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn debug_is_redacted_and_scrub_removes_the_key() {
        let key = ApiKey::new("  sk-secret-123 ").unwrap();
        assert_eq!(format!("{key:?}"), "ApiKey([REDACTED])");
        assert_eq!(key.expose(), "sk-secret-123");
        assert_eq!(key.scrub("bad key sk-secret-123!"), "bad key [REDACTED]!");
        assert_eq!(scrub(None, "sk-secret-123"), "sk-secret-123");
        assert!(ApiKey::new("  ").is_none());
    }
}
