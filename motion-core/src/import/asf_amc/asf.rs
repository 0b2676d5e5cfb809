//! [`Asf`]: an Acclaim skeleton file (bones, their rest directions and local axes, dofs and the
//! hierarchy).

use std::collections::HashMap;
use std::path::Path;
use std::str::SplitWhitespace;

use glam::DVec3;

use super::bone::{euler, rotation_order, AsfBone, Dof};
use super::lines::{invalid, numbered_lines};
use crate::files::read_bytes;
use crate::import::bvh::Axis;
use crate::import::error::{ImportError, ImportWarning};
use crate::import::values::{parse_finite, short_number};
use crate::limits::{MOCAP_FILE_BYTES, RIG_JOINTS};

/// Metres per inch: an ASF length unit is `0.0254 / length` m.
const METRES_PER_INCH: f64 = 0.0254;

/// A parsed ASF file: lengths in file units, rotations as quaternions.
#[derive(Debug, Clone)]
pub struct Asf {
    bones: Vec<AsfBone>,
    /// Every bone index, parents before children.
    order: Vec<usize>,
    /// Order in which the root's rotation values are applied (its `axis`).
    root_rotation_order: [Axis; 3],
    /// The root's `position`, ASF units.
    root_position: DVec3,
    /// Metres per ASF length unit (`0.0254 / length`).
    metres_per_unit: f64,
    /// Whether `:units angle` is `deg` (the default).
    degrees: bool,
}

/// A `begin` … `end` block of `:bonedata` while it is read.
struct Draft {
    line: usize,
    name: Option<String>,
    direction: Option<DVec3>,
    length: Option<f64>,
    /// `axis` angles (file unit) and order.
    axis: ([f64; 3], [Axis; 3]),
    dofs: Vec<Dof>,
}

/// A `:root` section while it is read.
struct RootDraft {
    line: usize,
    order: Vec<Dof>,
    rotation_order: [Axis; 3],
    position: DVec3,
    orientation: [f64; 3],
}

/// Which section the lines belong to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Section {
    Preamble,
    Version,
    Name,
    Units,
    Documentation,
    Root,
    Bonedata,
    Hierarchy,
}

/// `n` finite numbers from `tokens`, or an error naming `what` and the offending token.
fn numbers<const N: usize>(
    tokens: &mut std::str::SplitWhitespace<'_>,
    what: &str,
    at: impl Fn(String) -> ImportError,
) -> Result<[f64; N], ImportError> {
    let mut out = [0.0; N];
    for (k, slot) in out.iter_mut().enumerate() {
        let tok = tokens.next().unwrap_or("end of line");
        *slot = parse_finite(tok).ok_or_else(|| at(format!("{what} value {k}: `{tok}` is not a finite number")))?;
    }
    if let Some(extra) = tokens.next() {
        return Err(at(format!("{what}: unexpected `{extra}` after {N} values")));
    }
    Ok(out)
}

impl Asf {
    /// Reads a file of at most [`MOCAP_FILE_BYTES`] (bytes that are not UTF-8 are replaced, so
    /// only comments and names can suffer).
    pub fn read(path: &Path) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let bytes = read_bytes(path, &MOCAP_FILE_BYTES)?;
        Self::parse(&String::from_utf8_lossy(&bytes), path)
    }

    /// Parses ASF text; `path` is only used in messages. Bones are refused past [`RIG_JOINTS`].
    /// Warns about an ASF without `:units length` (inches are assumed).
    pub fn parse(text: &str, path: &Path) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let mut reader = AsfReader::new(path);
        for (line, content) in numbered_lines(text) {
            reader.last_line = line;
            reader.read_line(line, content)?;
        }
        reader.finish()
    }

    /// Every bone, the root first, in `:bonedata` order.
    pub fn bones(&self) -> &[AsfBone] {
        &self.bones
    }

    /// Index of the bone called `name` (exact match).
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }

    /// Every bone index with parents before children.
    pub fn order(&self) -> &[usize] {
        &self.order
    }

    /// Order in which the root's rotation values are applied (the root's `axis`).
    pub fn root_rotation_order(&self) -> [Axis; 3] {
        self.root_rotation_order
    }

    /// The root's rest `position`, ASF units.
    pub fn root_position(&self) -> DVec3 {
        self.root_position
    }

    /// Metres per ASF length unit from `:units length` (`0.0254 / length`).
    pub fn metres_per_unit(&self) -> f64 {
        self.metres_per_unit
    }

    /// Whether the ASF's angles are degrees (`:units angle deg`, the default).
    pub fn degrees(&self) -> bool {
        self.degrees
    }

    /// Start and end of every bone in the rest pose (all dofs zero), ASF units, world axes.
    pub fn rest_positions(&self) -> Vec<(DVec3, DVec3)> {
        let mut out = vec![(self.root_position, self.root_position); self.bones.len()];
        for &b in &self.order {
            let bone = &self.bones[b];
            if let Some(p) = bone.parent {
                let start = out[p].1;
                out[b] = (start, start + bone.direction * bone.length);
            }
        }
        out
    }
}

/// The error maker of one line: the message at that line, about the bone being read.
type At<'f> = &'f dyn Fn(String) -> ImportError;

/// An ASF file while it is read line by line.
struct AsfReader<'a> {
    /// The file, for messages.
    path: &'a Path,
    section: Section,
    seen: Vec<Section>,
    /// `:units length`, when given.
    length_scale: Option<f64>,
    /// Whether `:units angle` is `deg` (the default).
    degrees: bool,
    root: RootDraft,
    /// The bones whose `begin` … `end` blocks are closed.
    drafts: Vec<Draft>,
    /// The bone whose block is open.
    open: Option<Draft>,
    /// Hierarchy lines (line, parent, children), resolved once every bone is known.
    links: Vec<(usize, Vec<&'a str>)>,
    /// 0: before the hierarchy's `begin`, 1: inside, 2: after its `end`.
    hierarchy_state: u8,
    /// The last line read, for messages about what is missing at the end.
    last_line: usize,
}

impl<'a> AsfReader<'a> {
    /// Nothing read yet: degrees, and the root's default `order` and `axis`.
    fn new(path: &'a Path) -> Self {
        let root = RootDraft {
            line: 1,
            order: ["tx", "ty", "tz", "rx", "ry", "rz"].into_iter().filter_map(Dof::from_name).collect(),
            rotation_order: [Axis::X, Axis::Y, Axis::Z],
            position: DVec3::ZERO,
            orientation: [0.0; 3],
        };
        AsfReader {
            path,
            section: Section::Preamble,
            seen: Vec::new(),
            length_scale: None,
            degrees: true,
            root,
            drafts: Vec::new(),
            open: None,
            links: Vec::new(),
            hierarchy_state: 0,
            last_line: 1,
        }
    }

    /// One line (comment already cut off): a `:keyword` or a line of the current section.
    fn read_line(&mut self, line: usize, content: &'a str) -> Result<(), ImportError> {
        let mut tokens = content.split_whitespace();
        let Some(first) = tokens.next() else { return Ok(()) };
        let path = self.path;
        let bone = self.open.as_ref().and_then(|d| d.name.clone());
        let at = |message: String| invalid(path, line, bone.as_deref(), message);
        if let Some(keyword) = first.strip_prefix(':') {
            return self.start_section(keyword, first, line, &mut tokens, &at);
        }
        match self.section {
            Section::Preamble => Err(at(format!("expected a `:` keyword, found `{first}`"))),
            Section::Version | Section::Name => {
                Err(at(format!("unexpected `{first}` after {}", section_name(self.section))))
            }
            Section::Documentation => Ok(()),
            Section::Units => self.read_unit(first, &mut tokens, &at),
            Section::Root => self.root.read_field(first, &mut tokens, &at),
            Section::Bonedata => self.read_bone_line(first, line, &mut tokens, &at),
            Section::Hierarchy => self.read_hierarchy_line(first, line, content, &at),
        }
    }

    /// `:keyword` (`first` as written): a section starts; each comes once, and only `:version`
    /// and `:name` have values on their line.
    fn start_section(
        &mut self,
        keyword: &str,
        first: &str,
        line: usize,
        tokens: &mut SplitWhitespace<'_>,
        at: At<'_>,
    ) -> Result<(), ImportError> {
        let next = match keyword.to_ascii_lowercase().as_str() {
            "version" => Section::Version,
            "name" => Section::Name,
            "units" => Section::Units,
            "documentation" => Section::Documentation,
            "root" => Section::Root,
            "bonedata" => Section::Bonedata,
            "hierarchy" => Section::Hierarchy,
            _ => return Err(at(format!("unknown keyword `{first}`"))),
        };
        if let Some(d) = &self.open {
            return Err(invalid(self.path, d.line, d.name.as_deref(), "`begin` without `end`"));
        }
        if self.seen.contains(&next) {
            return Err(at(format!("a second `{first}`")));
        }
        if next == Section::Root {
            self.root.line = line;
        }
        if next != Section::Version && next != Section::Name && tokens.next().is_some() {
            return Err(at(format!("`{first}` takes no values on its line")));
        }
        self.seen.push(next);
        self.section = next;
        Ok(())
    }

    /// A `:units` line: `mass` (ignored), `length` (a positive scale) or `angle deg|rad`.
    fn read_unit(&mut self, first: &str, tokens: &mut SplitWhitespace<'_>, at: At<'_>) -> Result<(), ImportError> {
        match first.to_ascii_lowercase().as_str() {
            "mass" => {
                numbers::<1>(tokens, "mass", at)?;
            }
            "length" => {
                let [v] = numbers::<1>(tokens, "length", at)?;
                if v <= 0.0 {
                    return Err(at(format!("length scale {} is not positive", short_number(v))));
                }
                self.length_scale = Some(v);
            }
            "angle" => {
                self.degrees = match tokens.next().map(str::to_ascii_lowercase).as_deref() {
                    Some("deg") | Some("degree") | Some("degrees") => true,
                    Some("rad") | Some("radian") | Some("radians") => false,
                    other => {
                        return Err(at(format!(
                            "angle unit must be deg or rad, found `{}`",
                            other.unwrap_or("nothing")
                        )))
                    }
                };
            }
            other => return Err(at(format!("unknown unit `{other}` (expected mass, length or angle)"))),
        }
        Ok(())
    }

    /// A `:bonedata` line: `begin` opens a bone (refused past [`RIG_JOINTS`]), `end` closes it,
    /// anything else is a field of the open bone.
    fn read_bone_line(
        &mut self,
        first: &str,
        line: usize,
        tokens: &mut SplitWhitespace<'_>,
        at: At<'_>,
    ) -> Result<(), ImportError> {
        let key = first.to_ascii_lowercase();
        let Some(draft) = self.open.as_mut() else {
            if key != "begin" {
                return Err(at(format!("expected `begin`, found `{first}`")));
            }
            RIG_JOINTS.check(
                self.drafts.len() as u64 + 2,
                format_args!("{}: line {line}: the skeleton", self.path.display()),
            )?;
            self.open = Some(Draft {
                line,
                name: None,
                direction: None,
                length: None,
                axis: ([0.0; 3], [Axis::X, Axis::Y, Axis::Z]),
                dofs: Vec::new(),
            });
            return Ok(());
        };
        match key.as_str() {
            "begin" => Err(at("`begin` inside a bone; is an `end` missing?".into())),
            "end" => self.close_bone(),
            "id" | "bodymass" | "cofmass" | "limits" => Ok(()),
            _ if first.starts_with('(') => Ok(()),
            _ => draft.read_field(&key, first, tokens, at),
        }
    }

    /// `end`: the open bone is done; it needs a new name, a `direction` and a `length`.
    fn close_bone(&mut self) -> Result<(), ImportError> {
        let Some(d) = self.open.take() else { return Ok(()) };
        let path = self.path;
        let name = d.name.clone().ok_or_else(|| invalid(path, d.line, None, "bone without `name`"))?;
        let need = |what: &str| invalid(path, d.line, Some(&name), format!("no `{what}`"));
        if d.direction.is_none() {
            return Err(need("direction"));
        }
        if d.length.is_none() {
            return Err(need("length"));
        }
        if name == "root" || self.drafts.iter().any(|o| o.name.as_deref() == Some(name.as_str())) {
            return Err(invalid(path, d.line, Some(&name), "a second bone of this name"));
        }
        self.drafts.push(d);
        Ok(())
    }

    /// A `:hierarchy` line: `begin`, then `parent child…` lines, then `end`.
    fn read_hierarchy_line(
        &mut self,
        first: &str,
        line: usize,
        content: &'a str,
        at: At<'_>,
    ) -> Result<(), ImportError> {
        match (self.hierarchy_state, first.to_ascii_lowercase().as_str()) {
            (0, "begin") => self.hierarchy_state = 1,
            (1, "end") => self.hierarchy_state = 2,
            (1, _) => self.links.push((line, content.split_whitespace().collect())),
            (0, _) => return Err(at(format!("expected `begin`, found `{first}`"))),
            _ => return Err(at(format!("unexpected `{first}` after the hierarchy's `end`"))),
        }
        Ok(())
    }

    /// The skeleton, once every section is read: the bones with their axes in radians, linked by
    /// the hierarchy. Warns when `:units length` is missing (inches are assumed).
    fn finish(self) -> Result<(Asf, Vec<ImportWarning>), ImportError> {
        let path = self.path;
        let last_line = self.last_line;
        if let Some(d) = &self.open {
            return Err(invalid(path, d.line, d.name.as_deref(), "`begin` without `end`"));
        }
        if !self.seen.contains(&Section::Bonedata) {
            return Err(invalid(path, last_line, None, "missing `:bonedata`"));
        }
        if !self.seen.contains(&Section::Hierarchy) {
            return Err(invalid(path, last_line, None, "missing `:hierarchy`"));
        }
        if self.hierarchy_state != 2 {
            return Err(invalid(path, last_line, None, "the `:hierarchy` has no `begin` … `end`"));
        }
        let mut warnings = Vec::new();
        let length_scale = self.length_scale.unwrap_or_else(|| {
            warnings.push(ImportWarning {
                path: path.into(),
                message: "no `:units length`; lengths are taken as inches".into(),
            });
            1.0
        });
        let degrees = self.degrees;
        let to_radians = |a: [f64; 3]| if degrees { a.map(f64::to_radians) } else { a };
        let root = self.root;
        let mut bones = Vec::with_capacity(self.drafts.len() + 1);
        bones.push(AsfBone {
            name: "root".into(),
            parent: None,
            direction: DVec3::ZERO,
            length: 0.0,
            axis: euler(&root.rotation_order, to_radians(root.orientation)),
            dofs: root.order,
            line: root.line,
        });
        for d in self.drafts {
            bones.push(AsfBone {
                name: d.name.unwrap_or_default(),
                parent: None,
                direction: d.direction.unwrap_or_default(),
                length: d.length.unwrap_or_default(),
                axis: euler(&d.axis.1, to_radians(d.axis.0)),
                dofs: d.dofs,
                line: d.line,
            });
        }
        let order = resolve_hierarchy(&mut bones, &self.links, path)?;
        let asf = Asf {
            bones,
            order,
            root_rotation_order: root.rotation_order,
            root_position: root.position,
            metres_per_unit: METRES_PER_INCH / length_scale,
            degrees,
        };
        Ok((asf, warnings))
    }
}

impl RootDraft {
    /// A `:root` line: `order` (the AMC value order), `axis` (the rotation order), `position`
    /// or `orientation`.
    fn read_field(&mut self, first: &str, tokens: &mut SplitWhitespace<'_>, at: At<'_>) -> Result<(), ImportError> {
        match first.to_ascii_lowercase().as_str() {
            "order" => {
                let mut order = Vec::new();
                for tok in tokens {
                    match Dof::from_name(tok) {
                        Some(d) if d != Dof::Length && !order.contains(&d) => order.push(d),
                        _ => {
                            return Err(at(format!("root order: `{tok}` is not one of TX TY TZ RX RY RZ (each once)")))
                        }
                    }
                }
                self.order = order;
            }
            "axis" => {
                let tok = tokens.next().unwrap_or("nothing");
                self.rotation_order = rotation_order(tok)
                    .ok_or_else(|| at(format!("unknown rotation order `{tok}` (expected e.g. XYZ)")))?;
            }
            "position" => self.position = DVec3::from_array(numbers(tokens, "position", at)?),
            "orientation" => self.orientation = numbers(tokens, "orientation", at)?,
            other => return Err(at(format!("unknown root field `{other}`"))),
        }
        Ok(())
    }
}

impl Draft {
    /// A field line of an open bone (`key` is `first` in lower case): `name`, `direction`,
    /// `length`, `axis ax ay az ORDER` or `dof`.
    fn read_field(
        &mut self,
        key: &str,
        first: &str,
        tokens: &mut SplitWhitespace<'_>,
        at: At<'_>,
    ) -> Result<(), ImportError> {
        match key {
            "name" => {
                let name = tokens.next().ok_or_else(|| at("`name` without a name".into()))?;
                self.name = Some(name.to_owned());
            }
            "direction" => {
                let d = DVec3::from_array(numbers(tokens, "direction", at)?);
                let unit = d.try_normalize().ok_or_else(|| at("direction is zero".into()))?;
                self.direction = Some(unit);
            }
            "length" => {
                let [v] = numbers::<1>(tokens, "length", at)?;
                if v < 0.0 {
                    return Err(at(format!("length {} is negative", short_number(v))));
                }
                self.length = Some(v);
            }
            "axis" => {
                let mut angles = [0.0; 3];
                for (k, slot) in angles.iter_mut().enumerate() {
                    let tok = tokens.next().unwrap_or("end of line");
                    *slot = parse_finite(tok)
                        .ok_or_else(|| at(format!("axis value {k}: `{tok}` is not a finite number")))?;
                }
                let tok = tokens.next().unwrap_or("nothing");
                let order = rotation_order(tok)
                    .ok_or_else(|| at(format!("unknown rotation order `{tok}` (expected e.g. XYZ)")))?;
                self.axis = (angles, order);
            }
            "dof" => {
                let mut dofs = Vec::new();
                for tok in tokens {
                    match Dof::from_name(tok) {
                        Some(d) if !dofs.contains(&d) => dofs.push(d),
                        Some(_) => return Err(at(format!("dof `{tok}` listed twice"))),
                        None => return Err(at(format!("unknown dof `{tok}` (expected rx ry rz tx ty tz l)"))),
                    }
                }
                self.dofs = dofs;
            }
            _ => return Err(at(format!("unknown bone field `{first}`"))),
        }
        Ok(())
    }
}

/// The name of a section's keyword.
fn section_name(section: Section) -> &'static str {
    match section {
        Section::Preamble => "the start",
        Section::Version => "`:version`",
        Section::Name => "`:name`",
        Section::Units => "`:units`",
        Section::Documentation => "`:documentation`",
        Section::Root => "`:root`",
        Section::Bonedata => "`:bonedata`",
        Section::Hierarchy => "`:hierarchy`",
    }
}

/// Sets each bone's parent from the hierarchy lines and returns the bones parents first. Fails
/// on an undefined bone, a bone with two parents, the root as a child, a cycle, or a bone
/// outside the hierarchy.
fn resolve_hierarchy(
    bones: &mut [AsfBone],
    links: &[(usize, Vec<&str>)],
    path: &Path,
) -> Result<Vec<usize>, ImportError> {
    let index: HashMap<&str, usize> = bones.iter().enumerate().map(|(i, b)| (b.name.as_str(), i)).collect();
    let mut parent_line: Vec<Option<usize>> = vec![None; bones.len()];
    let mut parents: Vec<Option<usize>> = vec![None; bones.len()];
    for (line, names) in links {
        let find = |name: &str| {
            index.get(name).copied().ok_or_else(|| invalid(path, *line, Some(name), "not defined in `:bonedata`"))
        };
        let Some((parent, children)) = names.split_first() else { continue };
        let p = find(parent)?;
        if children.is_empty() {
            return Err(invalid(path, *line, Some(*parent), "a hierarchy line without children"));
        }
        for child in children {
            let c = find(child)?;
            if c == 0 {
                return Err(invalid(path, *line, Some(*child), "the root cannot be a child"));
            }
            if let (Some(old), Some(old_line)) = (parents[c], parent_line[c]) {
                return Err(invalid(
                    path,
                    *line,
                    Some(*child),
                    format!("a second parent: {} here, {} on line {old_line}", parent, bones[old].name),
                ));
            }
            parents[c] = Some(p);
            parent_line[c] = Some(*line);
        }
    }
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); bones.len()];
    for (c, p) in parents.iter().enumerate() {
        if let Some(p) = p {
            children[*p].push(c);
        }
    }
    let mut order = vec![0];
    let mut k = 0;
    while let Some(&b) = order.get(k) {
        order.extend(children[b].iter().copied());
        k += 1;
    }
    let mut reached = vec![false; bones.len()];
    for &b in &order {
        reached[b] = true;
    }
    if let Some(lost) = reached.iter().position(|r| !r) {
        let bone = &bones[lost];
        return Err(match parent_line[lost] {
            Some(line) => {
                invalid(path, line, Some(&bone.name), "part of a cycle in the `:hierarchy`, not connected to the root")
            }
            None => invalid(path, bone.line, Some(&bone.name), "not in the `:hierarchy`"),
        });
    }
    for (bone, parent) in bones.iter_mut().zip(parents) {
        bone.parent = parent;
    }
    Ok(order)
}
