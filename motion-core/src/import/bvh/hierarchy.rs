//! The HIERARCHY section of a BVH file: nodes ([`BvhJoint`]) with their OFFSETs and
//! [`Channel`]s, read as a token stream.

use std::iter::Peekable;
use std::path::Path;

use glam::DVec3;

use super::error::invalid;
use crate::import::error::ImportError;
use crate::import::values::parse_finite;
use crate::limits::RIG_JOINTS;

/// A coordinate axis of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// x.
    X,
    /// y.
    Y,
    /// z.
    Z,
}

/// One channel of a joint: a translation or an Euler rotation (degrees) about a file axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    /// `Xposition`, `Yposition`, `Zposition`.
    Position(Axis),
    /// `Xrotation`, `Yrotation`, `Zrotation`.
    Rotation(Axis),
}

impl Channel {
    /// Parses a channel name (ASCII case-insensitive, as some exporters write `XROTATION`).
    fn from_name(s: &str) -> Option<Channel> {
        let lower = s.to_ascii_lowercase();
        let axis = match lower.as_bytes().first() {
            Some(b'x') => Axis::X,
            Some(b'y') => Axis::Y,
            Some(b'z') => Axis::Z,
            _ => return None,
        };
        match &lower[1..] {
            "position" => Some(Channel::Position(axis)),
            "rotation" => Some(Channel::Rotation(axis)),
            _ => None,
        }
    }

    /// The name as written in files.
    pub fn name(self) -> &'static str {
        match self {
            Channel::Position(Axis::X) => "Xposition",
            Channel::Position(Axis::Y) => "Yposition",
            Channel::Position(Axis::Z) => "Zposition",
            Channel::Rotation(Axis::X) => "Xrotation",
            Channel::Rotation(Axis::Y) => "Yrotation",
            Channel::Rotation(Axis::Z) => "Zrotation",
        }
    }
}

/// A node of the hierarchy: the `ROOT`, a `JOINT`, or an `End Site` (no channels).
#[derive(Debug, Clone, PartialEq)]
pub struct BvhJoint {
    /// The name as written; end sites are called "`<parent>` End Site".
    pub name: String,
    /// Index of the parent node; `None` for the root.
    pub parent: Option<usize>,
    /// Position in the parent's frame, file units and axes.
    pub offset: DVec3,
    /// Channels in the order their values appear on a motion line.
    pub channels: Vec<Channel>,
    /// Whether this is an `End Site`.
    pub end_site: bool,
    /// 1-based line of its `ROOT`/`JOINT`/`End Site` keyword.
    pub line: usize,
}

/// A hierarchy node while its block is being read.
struct Draft {
    joint: BvhJoint,
    has_offset: bool,
    has_channels: bool,
}

/// The hierarchy read so far: its nodes in file order, the blocks still open, and the node
/// whose `{` must come next.
struct Tree<'p> {
    /// The file, for messages.
    path: &'p Path,
    drafts: Vec<Draft>,
    /// Nodes whose blocks are open, innermost last.
    stack: Vec<usize>,
    /// The node just named, whose `{` is due.
    pending: Option<usize>,
}

/// Reads the HIERARCHY tokens (each with its 1-based line) without recursion, so deeply nested
/// input cannot overflow the stack.
pub(super) fn parse_hierarchy<'a>(
    tokens: impl Iterator<Item = (&'a str, usize)>,
    last_line: usize,
    path: &Path,
) -> Result<Vec<BvhJoint>, ImportError> {
    let mut it = tokens.peekable();
    match it.next() {
        Some(("HIERARCHY", _)) => {}
        Some((tok, line)) => return Err(invalid(path, line, None, format!("expected HIERARCHY, found `{tok}`"))),
        None => return Err(invalid(path, last_line, None, "expected HIERARCHY")),
    }
    let mut tree = Tree { path, drafts: Vec::new(), stack: Vec::new(), pending: None };
    while let Some((tok, line)) = it.next() {
        if let Some(p) = tree.pending {
            if tok != "{" {
                return Err(tree.invalid(line, Some(p), format!("expected `{{`, found `{tok}`")));
            }
        }
        match tok {
            "ROOT" | "JOINT" => tree.open_joint(tok, line, &mut it)?,
            "End" => tree.open_end_site(line, &mut it)?,
            "{" => tree.open_block(line)?,
            "}" => tree.close_block(line)?,
            "OFFSET" => tree.read_offset(line, &mut it)?,
            "CHANNELS" => tree.read_channels(line, &mut it)?,
            other => return Err(tree.invalid(line, tree.current(), format!("unexpected `{other}`"))),
        }
    }
    tree.finish(last_line)
}

impl Tree<'_> {
    /// The innermost open block's node.
    fn current(&self) -> Option<usize> {
        self.stack.last().copied()
    }

    /// An error at `line` about `node`, when given.
    fn invalid(&self, line: usize, node: Option<usize>, message: impl Into<String>) -> ImportError {
        let name = node.and_then(|i| self.drafts.get(i)).map(|d| d.joint.name.clone());
        invalid(self.path, line, name.as_deref(), message)
    }

    /// Adds a node whose `{` must come next, refusing the [`RIG_JOINTS`]+1st (checked before
    /// each node is added, so a huge hierarchy stops at the first node over).
    fn push(&mut self, joint: BvhJoint) -> Result<(), ImportError> {
        let line = joint.line;
        RIG_JOINTS
            .check(self.drafts.len() as u64 + 1, format_args!("{}: line {line}: the rig", self.path.display()))?;
        self.pending = Some(self.drafts.len());
        self.drafts.push(Draft { joint, has_offset: false, has_channels: false });
        Ok(())
    }

    /// `ROOT name` or `JOINT name` (the name is the rest of the line up to a `{`): a node under
    /// the innermost open block; a second ROOT, a JOINT outside any block and children of an
    /// End Site are refused.
    fn open_joint<'a, I: Iterator<Item = (&'a str, usize)>>(
        &mut self,
        keyword: &str,
        line: usize,
        it: &mut Peekable<I>,
    ) -> Result<(), ImportError> {
        let current = self.current();
        if keyword == "ROOT" && !self.drafts.is_empty() {
            return Err(invalid(self.path, line, None, "a second ROOT: only one skeleton per file is supported"));
        }
        if keyword == "JOINT" && current.is_none() {
            return Err(invalid(self.path, line, None, "JOINT outside a joint's braces"));
        }
        if current.is_some_and(|c| self.drafts[c].joint.end_site) {
            return Err(self.invalid(line, current, "an End Site cannot have children"));
        }
        let mut parts = Vec::new();
        while let Some(&(t, l)) = it.peek() {
            if l != line || t == "{" {
                break;
            }
            parts.push(t);
            it.next();
        }
        if parts.is_empty() {
            return Err(invalid(self.path, line, None, format!("{keyword} without a name")));
        }
        let name = parts.join(" ");
        self.push(BvhJoint { name, parent: current, offset: DVec3::ZERO, channels: Vec::new(), end_site: false, line })
    }

    /// `End Site`: a node without channels under the innermost open joint, named after it.
    fn open_end_site<'a, I: Iterator<Item = (&'a str, usize)>>(
        &mut self,
        line: usize,
        it: &mut Peekable<I>,
    ) -> Result<(), ImportError> {
        let current = self.current();
        if !matches!(it.next(), Some(("Site", l)) if l == line) {
            return Err(self.invalid(line, current, "expected `End Site`"));
        }
        let Some(parent) = current.filter(|c| !self.drafts[*c].joint.end_site) else {
            return Err(invalid(self.path, line, None, "End Site outside a joint"));
        };
        let name = format!("{} End Site", self.drafts[parent].joint.name);
        self.push(BvhJoint {
            name,
            parent: Some(parent),
            offset: DVec3::ZERO,
            channels: Vec::new(),
            end_site: true,
            line,
        })
    }

    /// `{`: opens the block of the node just named.
    fn open_block(&mut self, line: usize) -> Result<(), ImportError> {
        match self.pending.take() {
            Some(i) => self.stack.push(i),
            None => return Err(self.invalid(line, self.current(), "unexpected `{`")),
        }
        Ok(())
    }

    /// `}`: closes the innermost block, whose node must have had its OFFSET (and, for a joint,
    /// its CHANNELS).
    fn close_block(&mut self, line: usize) -> Result<(), ImportError> {
        let Some(i) = self.stack.pop() else {
            return Err(invalid(self.path, line, None, "unmatched `}`"));
        };
        let d = &self.drafts[i];
        if !d.has_offset {
            return Err(invalid(self.path, d.joint.line, Some(&d.joint.name), "no OFFSET"));
        }
        if !d.joint.end_site && !d.has_channels {
            return Err(invalid(self.path, d.joint.line, Some(&d.joint.name), "no CHANNELS line"));
        }
        Ok(())
    }

    /// The innermost open node and its name, for a `keyword` line that must be inside one.
    fn innermost(&self, line: usize, keyword: &str) -> Result<(usize, Option<String>), ImportError> {
        let Some(i) = self.current() else {
            return Err(invalid(self.path, line, None, format!("{keyword} outside a joint")));
        };
        Ok((i, self.drafts.get(i).map(|d| d.joint.name.clone())))
    }

    /// `OFFSET x y z` (file units) of the innermost open node, once.
    fn read_offset<'a, I: Iterator<Item = (&'a str, usize)>>(
        &mut self,
        line: usize,
        it: &mut Peekable<I>,
    ) -> Result<(), ImportError> {
        let (i, name) = self.innermost(line, "OFFSET")?;
        if self.drafts[i].has_offset {
            return Err(invalid(self.path, line, name.as_deref(), "a second OFFSET"));
        }
        let mut v = [0.0; 3];
        for (k, slot) in v.iter_mut().enumerate() {
            let tok = it.next().map_or("end of hierarchy", |(t, _)| t);
            *slot = parse_finite(tok).ok_or_else(|| {
                invalid(self.path, line, name.as_deref(), format!("OFFSET value {k}: `{tok}` is not a finite number"))
            })?;
        }
        self.drafts[i].joint.offset = DVec3::from_array(v);
        self.drafts[i].has_offset = true;
        Ok(())
    }

    /// `CHANNELS n name…` of the innermost open joint, once (End Sites have none).
    fn read_channels<'a, I: Iterator<Item = (&'a str, usize)>>(
        &mut self,
        line: usize,
        it: &mut Peekable<I>,
    ) -> Result<(), ImportError> {
        let (i, name) = self.innermost(line, "CHANNELS")?;
        if self.drafts[i].joint.end_site {
            return Err(invalid(self.path, line, name.as_deref(), "an End Site cannot have CHANNELS"));
        }
        if self.drafts[i].has_channels {
            return Err(invalid(self.path, line, name.as_deref(), "a second CHANNELS line"));
        }
        let count = it
            .next()
            .and_then(|(t, _)| t.parse::<usize>().ok())
            .ok_or_else(|| invalid(self.path, line, name.as_deref(), "CHANNELS must be followed by a channel count"))?;
        let mut channels = Vec::new();
        while channels.len() < count {
            match it.peek().and_then(|(t, _)| Channel::from_name(t)) {
                Some(c) => {
                    channels.push(c);
                    it.next();
                }
                None => {
                    return Err(invalid(
                        self.path,
                        line,
                        name.as_deref(),
                        format!("CHANNELS declares {count} channels but lists {}", channels.len()),
                    ))
                }
            }
        }
        self.drafts[i].joint.channels = channels;
        self.drafts[i].has_channels = true;
        Ok(())
    }

    /// The nodes, once every block is closed; at least the ROOT.
    fn finish(self, last_line: usize) -> Result<Vec<BvhJoint>, ImportError> {
        if let Some(p) = self.pending {
            return Err(invalid(
                self.path,
                last_line,
                Some(&self.drafts[p].joint.name),
                "hierarchy ends before its `{`",
            ));
        }
        if let Some(&open) = self.stack.last() {
            let d = &self.drafts[open].joint;
            return Err(invalid(
                self.path,
                last_line,
                Some(&d.name),
                format!("the block opened on line {} is never closed", d.line),
            ));
        }
        if self.drafts.is_empty() {
            return Err(invalid(self.path, last_line, None, "the hierarchy has no ROOT"));
        }
        Ok(self.drafts.into_iter().map(|d| d.joint).collect())
    }
}
