//! Semantic validation of a [`TaskProgram`]: what the types cannot say. Every error carries the JSON
//! path of its field.

use std::collections::HashSet;

use super::error::{Problem, ProgramError};
use super::expr::{field, index, Airborne, Count, EventRegion, Events, Expr, FootContact, SelfCollision};
use super::limits::MAX_FRAMES;
use super::quantity::{CarriedLoad, Condition, FrameRange, FrameRef, FrameSelection, Point, Quantity};
use super::scene::{JointSet, Primitive};
use super::task::{RelationalParse, TaskProgram};
use crate::limits::{PROGRAM_CONSTRAINTS, PROGRAM_FRAMES, PROGRAM_TEXT_CHARS};
use crate::skeleton::Joint;

/// Largest |coordinate| or length of a scene, in metres.
const MAX_ABS_M: f64 = 100.0;
/// Largest weight, NOT margin, count sharpness and direction component.
const MAX_FACTOR: f64 = 1e6;

impl TaskProgram {
    /// Checks what deserialisation cannot: finite, non-absurd numbers (|coordinate| ≤ 100 m),
    /// frames inside the clip (for each signal's own length), consistent fields (target length,
    /// interval order, gap width vs margin), unique ids and a relational parse naming existing,
    /// distinct constraints with a confidence in [0, 1]. Returns every problem found.
    pub fn validate(&self) -> Result<(), Vec<ProgramError>> {
        let mut checker = Checker { frames: self.frames, errors: Vec::new() };
        checker.program(self);
        if checker.errors.is_empty() {
            Ok(())
        } else {
            Err(checker.errors)
        }
    }
}

struct Checker {
    frames: u32,
    errors: Vec<ProgramError>,
}

impl Checker {
    fn push(&mut self, path: impl Into<String>, problem: Problem) {
        self.errors.push(ProgramError::new(path, problem));
    }

    fn inconsistent(&mut self, path: impl Into<String>, message: impl Into<String>) {
        self.push(path, Problem::Inconsistent(message.into()));
    }

    /// `value` finite and in `[min, max]`; false (and an error) otherwise.
    fn number(&mut self, path: &str, value: f64, min: f64, max: f64, unit: &'static str) -> bool {
        if !value.is_finite() {
            self.push(path, Problem::NonFinite { value });
            false
        } else if value < min || value > max {
            self.push(path, Problem::OutOfRange { value, min, max, unit });
            false
        } else {
            true
        }
    }

    fn point_m(&mut self, path: &str, point: &[f64; 3]) {
        for (i, &value) in point.iter().enumerate() {
            self.number(&index(path, i), value, -MAX_ABS_M, MAX_ABS_M, "m");
        }
    }

    fn direction(&mut self, path: &str, vector: &[f64; 3]) {
        let finite = vector
            .iter()
            .enumerate()
            .all(|(i, &value)| self.number(&index(path, i), value, -MAX_FACTOR, MAX_FACTOR, ""));
        if finite && vector.iter().map(|v| v * v).sum::<f64>() < 1e-12 {
            self.inconsistent(path, "a direction must have non-zero length");
        }
    }

    fn interval_m(&mut self, path: &str, range: &[f64; 2]) {
        let lo = self.number(&index(path, 0), range[0], -MAX_ABS_M, MAX_ABS_M, "m");
        let hi = self.number(&index(path, 1), range[1], -MAX_ABS_M, MAX_ABS_M, "m");
        if lo && hi && range[0] >= range[1] {
            self.inconsistent(path, format!("range [{}, {}] is empty: min must be < max", range[0], range[1]));
        }
    }

    /// Words for people and the prior: at most [`PROGRAM_TEXT_CHARS`] characters and no control
    /// characters other than newline and tab (they would reach terminals and reports raw).
    fn words(&mut self, path: &str, text: &str) {
        if let Err(over) = PROGRAM_TEXT_CHARS.check(text.chars().count() as u64, "the text") {
            self.push(path, over.into());
        }
        if let Some((at, c)) = text.chars().enumerate().find(|(_, c)| c.is_control() && !matches!(c, '\n' | '\t')) {
            self.inconsistent(path, format!("character {at} is the control character {c:?}; write plain text"));
        }
    }

    fn distinct_joints(&mut self, path: &str, joints: &[Joint]) {
        let mut seen = HashSet::new();
        for (i, joint) in joints.iter().enumerate() {
            if !seen.insert(joint) {
                self.inconsistent(index(path, i), format!("joint `{}` is listed twice", joint.name()));
            }
        }
    }

    fn program(&mut self, program: &TaskProgram) {
        if program.frames == 0 {
            self.push("frames", Problem::OutOfRange { value: 0.0, min: 1.0, max: f64::from(MAX_FRAMES), unit: "" });
            return;
        }
        if let Err(over) = PROGRAM_FRAMES.check(u64::from(program.frames), "the clip length") {
            self.push("frames", over.into());
            return;
        }
        if let Err(over) = PROGRAM_CONSTRAINTS.check(program.constraints.len() as u64, "the program's constraint count")
        {
            self.push("constraints", over.into());
            return;
        }
        if program.constraints.is_empty() {
            self.push("constraints", Problem::Empty);
        }
        self.words("text", &program.text);
        let mut ids = HashSet::new();
        for (i, constraint) in program.constraints.iter().enumerate() {
            let path = index("constraints", i);
            let id = &constraint.id;
            let well_formed = id.len() <= 5
                && id
                    .strip_prefix('c')
                    .is_some_and(|n| !n.is_empty() && !n.starts_with('0') && n.bytes().all(|b| b.is_ascii_digit()));
            if !well_formed {
                self.inconsistent(
                    field(&path, "id"),
                    format!(
                        "id `{}` must be `c` and a number from 1 to 9999 without leading zeros (`c1`, `c2`, ..., \
                         `c9999`)",
                        id.chars().take(40).collect::<String>().escape_debug()
                    ),
                );
            }
            if let Some(description) = &constraint.description {
                self.words(&field(&path, "description"), description);
            }
            if !ids.insert(id.as_str()) {
                self.push(field(&path, "id"), Problem::DuplicateId(id.clone()));
            }
            if let Some(weight) = constraint.weight {
                self.number(&field(&path, "weight"), weight, 0.0, MAX_FACTOR, "");
            }
            constraint.expr.walk(&field(&path, "expr"), &mut |expr, at| self.expr(at, expr));
        }
        if let Some(parse) = &program.relational_parse {
            self.relational_parse(parse, &ids);
        }
    }

    fn relational_parse(&mut self, parse: &RelationalParse, ids: &HashSet<&str>) {
        let path = "relational_parse";
        let known = |checker: &mut Checker, at: String, id: &str| {
            if !ids.contains(id) {
                checker.push(at, Problem::UnknownId(id.to_owned()));
            }
        };
        known(self, field(path, "most_difficult"), &parse.most_difficult);
        let mut seen = HashSet::from([parse.most_difficult.as_str()]);
        for (name, list) in [("connected", &parse.connected), ("conflicting", &parse.conflicting)] {
            for (i, id) in list.iter().enumerate() {
                let at = index(&field(path, name), i);
                known(self, at.clone(), id);
                if !seen.insert(id.as_str()) {
                    let message = if *id == parse.most_difficult {
                        format!("`{id}` is the most difficult constraint itself")
                    } else {
                        format!("`{id}` is listed twice in connected/conflicting")
                    };
                    self.push(at, Problem::Inconsistent(message));
                }
            }
        }
        self.number(&field(path, "retrieval_confidence"), parse.retrieval_confidence, 0.0, 1.0, "");
    }

    /// Checks a quantity; returns its number of frames when it has any.
    fn quantity(&mut self, path: &str, quantity: &Quantity) -> Option<u32> {
        let n = self.frames.checked_sub(quantity.lag()).filter(|&n| n > 0);
        if n.is_none() {
            self.inconsistent(
                path,
                format!("needs at least {} frames, the clip has {}", quantity.lag() + 1, self.frames),
            );
        }
        match quantity {
            Quantity::Position(q) => self.point(&field(path, "of"), &q.of),
            Quantity::Displacement(q) => {
                self.point(&field(path, "of"), &q.of);
                if let Some(n) = n {
                    self.frame_ref(&field(path, "since"), q.since, n);
                }
            }
            Quantity::Velocity(q) | Quantity::Speed(q) | Quantity::Acceleration(q) => {
                self.point(&field(path, "of"), &q.of)
            }
            Quantity::Distance(q) => {
                self.point(&field(path, "a"), &q.a);
                self.point(&field(path, "b"), &q.b);
                if q.a == q.b {
                    self.inconsistent(path, "the distance of a point to itself is always 0");
                }
            }
            Quantity::DistanceToLine(q) => {
                self.point(&field(path, "of"), &q.of);
                self.point_m(&field(path, "point_m"), &q.point_m);
                self.direction(&field(path, "direction"), &q.direction);
            }
            Quantity::DistanceToPlane(q) => {
                self.point(&field(path, "of"), &q.of);
                self.point_m(&field(path, "point_m"), &q.point_m);
                self.direction(&field(path, "normal"), &q.normal);
            }
        }
        n
    }

    fn point(&mut self, path: &str, point: &Point) {
        match point {
            Point::Joint(_) => {}
            Point::Midpoint([a, b]) => self.distinct_joints(&field(path, "midpoint"), &[*a, *b]),
            Point::CentreOfMass(com) => {
                if let Some(load) = &com.load {
                    self.load(&field(&field(path, "centre_of_mass"), "load"), load);
                }
            }
            Point::FixedM(p) => self.point_m(&field(path, "fixed_m"), p),
        }
    }

    fn load(&mut self, at: &str, load: &CarriedLoad) {
        self.distinct_joints(&field(at, "between"), &load.between);
        if self.number(&field(at, "mass_ratio"), load.mass_ratio, 0.0, 100.0, "") && load.mass_ratio == 0.0 {
            self.inconsistent(field(at, "mass_ratio"), "a carried load needs a positive mass");
        }
    }

    /// A scalar quantity (conditions, counts): one component.
    fn scalar(&mut self, path: &str, quantity: &Quantity) -> Option<u32> {
        let n = self.quantity(path, quantity);
        if quantity.components() != 1 {
            self.inconsistent(path, format!("must be a scalar; it has {} components", quantity.components()));
        }
        n
    }

    fn frame_ref(&mut self, path: &str, frame: FrameRef, n: u32) {
        if let FrameRef::Fraction(f) = frame {
            let at = field(path, "fraction");
            if !self.number(&at, f, 0.0, 1.0, "") {
                return;
            }
        }
        if frame.resolve(n).is_none() {
            let shown = match frame {
                FrameRef::Frame(f) => f.to_string(),
                other => format!("{other:?}"),
            };
            let at = if matches!(frame, FrameRef::Frame(_)) { field(path, "frame") } else { path.to_owned() };
            self.push(at, Problem::FrameOutsideClip { frame: shown, last: n.saturating_sub(1) });
        }
    }

    fn frames(&mut self, path: &str, selection: &FrameSelection, n: u32) {
        match selection {
            FrameSelection::All => {}
            FrameSelection::Keyframes(keys) => {
                for (i, key) in keys.iter().enumerate() {
                    self.frame_ref(&index(&field(path, "keyframes"), i), *key, n);
                }
            }
            FrameSelection::Range(range) => self.frame_range(&field(path, "range"), range, n),
        }
    }

    /// Both ends inside a signal of `n` frames, `from` not after `to`.
    fn frame_range(&mut self, at: &str, range: &FrameRange, n: u32) {
        self.frame_ref(&field(at, "from"), range.from, n);
        self.frame_ref(&field(at, "to"), range.to, n);
        if let (Some(from), Some(to)) = (range.from.resolve(n), range.to.resolve(n)) {
            if from > to {
                self.inconsistent(at, format!("frame range {from}..={to} is empty"));
            }
        }
    }

    fn condition(&mut self, path: &str, condition: &Condition) {
        self.scalar(&field(path, "of"), &condition.of);
        let limit = condition.of.unit().absurd_limit();
        let unit = unit_name(&condition.of);
        let min = condition.min.filter(|&v| self.number(&field(path, "min"), v, -limit, limit, unit));
        let max = condition.max.filter(|&v| self.number(&field(path, "max"), v, -limit, limit, unit));
        match (condition.min, condition.max, min, max) {
            (None, None, ..) => self.inconsistent(path, "a condition needs `min`, `max` or both"),
            (_, _, Some(lo), Some(hi)) if lo >= hi => {
                self.inconsistent(path, format!("condition range ({lo}, {hi}) is empty: min must be < max"))
            }
            _ => {}
        }
    }

    /// A comparison leaf: quantity, bound values, frames, condition.
    fn compare(&mut self, path: &str, quantity: &Quantity, bounds: &[(String, f64)], frames: &FrameSelection) {
        let n = self.quantity(&field(path, "quantity"), quantity);
        let limit = quantity.unit().absurd_limit();
        for (at, value) in bounds {
            self.number(at, *value, -limit, limit, unit_name(quantity));
        }
        if let Some(n) = n {
            self.frames(&field(path, "frames"), frames, n);
        }
    }

    fn expr(&mut self, path: &str, expr: &Expr) {
        match expr {
            Expr::Equal(e) => {
                let at = field(path, "target");
                let bounds: Vec<_> = e.target.iter().enumerate().map(|(i, &v)| (index(&at, i), v)).collect();
                self.compare(path, &e.quantity, &bounds, &e.frames);
                if e.target.len() != e.quantity.components() {
                    self.inconsistent(
                        at,
                        format!(
                            "has {} values; the quantity has {} component(s)",
                            e.target.len(),
                            e.quantity.components()
                        ),
                    );
                }
                if let Some(when) = &e.when {
                    self.condition(&field(path, "when"), when);
                }
            }
            Expr::LessThan(e) => {
                self.compare(path, &e.quantity, &[(field(path, "max"), e.max)], &e.frames);
                if let Some(when) = &e.when {
                    self.condition(&field(path, "when"), when);
                }
            }
            Expr::GreaterThan(e) => {
                self.compare(path, &e.quantity, &[(field(path, "min"), e.min)], &e.frames);
                if let Some(when) = &e.when {
                    self.condition(&field(path, "when"), when);
                }
            }
            // Their arguments are visited by the walk.
            Expr::And(_) | Expr::Or(_) => {}
            Expr::Not(not) => {
                let at = field(path, "margin");
                if self.number(&at, not.margin, 0.0, MAX_FACTOR, "") && not.margin == 0.0 {
                    self.inconsistent(at, "a NOT margin of 0 is always satisfied");
                }
            }
            Expr::Count(count) => self.count(path, count),
            Expr::Steps(_) => {}
            Expr::Scene(scene) => {
                if let JointSet::Only(joints) = &scene.body.joints {
                    self.distinct_joints(&field(&field(path, "body"), "joints.only"), joints);
                }
                self.primitive(&field(path, "primitive"), &scene.primitive);
                self.frames(&field(path, "frames"), &scene.frames, self.frames);
                if let Some(when) = &scene.when {
                    self.condition(&field(path, "when"), when);
                }
            }
            Expr::Events(e) => self.events(path, e),
            Expr::Airborne(e) => self.airborne(path, e),
            Expr::Carry(e) => {
                self.distinct_joints(&field(path, "hands"), &e.hands);
                let at = field(path, "diameter_m");
                if self.number(&at, e.diameter_m, 0.0, MAX_ABS_M, "m") && e.diameter_m == 0.0 {
                    self.inconsistent(at, "an object of diameter 0 is no object");
                }
                self.number(&field(path, "clearance_m"), e.clearance_m, 0.0, MAX_ABS_M, "m");
                self.frames(&field(path, "frames"), &e.frames, self.frames);
            }
            Expr::BoneDirection(e) => {
                if e.joint.parent().is_none() {
                    self.inconsistent(field(path, "joint"), "the pelvis is the root: it has no bone");
                }
                self.direction(&field(path, "direction"), &e.direction);
                self.frames(&field(path, "frames"), &e.frames, self.frames);
            }
            Expr::FootContact(e) => self.foot_contact(path, e),
            Expr::SelfCollision(e) => self.self_collision(path, e),
            Expr::ComInSupport(e) => {
                self.number(&field(path, "margin_m"), e.margin_m, 0.0, MAX_ABS_M, "m");
                if let Some(load) = &e.load {
                    self.load(&field(path, "load"), load);
                }
                self.frames(&field(path, "frames"), &e.frames, self.frames);
            }
            Expr::StayNearInitial(e) => {
                let mut shortest = Some(self.frames);
                for (i, quantity) in e.quantities.iter().enumerate() {
                    let n = self.quantity(&index(&field(path, "quantities"), i), quantity);
                    shortest = shortest.zip(n).map(|(a, b)| a.min(b));
                }
                if let Some(n) = shortest {
                    self.frames(&field(path, "frames"), &e.frames, n);
                }
            }
        }
    }

    fn count(&mut self, path: &str, count: &Count) {
        let mut shortest = Some(self.frames);
        let first_unit = count.signals.as_slice()[0].unit();
        for (i, signal) in count.signals.iter().enumerate() {
            let at = index(&field(path, "signals"), i);
            let n = self.scalar(&at, signal);
            shortest = shortest.zip(n).map(|(a, b)| a.min(b));
            if signal.unit() != first_unit {
                self.inconsistent(at, format!("is in {}, the first signal in {first_unit}", signal.unit()));
            }
        }
        let limit = first_unit.absurd_limit();
        self.number(&field(path, "threshold"), count.threshold, -limit, limit, unit_name(&count.signals[0]));
        let at = field(path, "sharpness");
        if self.number(&at, count.sharpness, 0.0, MAX_FACTOR, "") && count.sharpness == 0.0 {
            self.inconsistent(at, "a sharpness of 0 makes every sigmoid 0.5");
        }
        let Some(n) = shortest else { return };
        if n < 3 {
            self.inconsistent(path, "counting extrema needs signals of at least 3 frames");
        }
        let most = u64::from(n.saturating_sub(1) / 2) * count.signals.len() as u64;
        if u64::from(count.target_count) > most {
            self.inconsistent(
                field(path, "target_count"),
                format!("{} extrema cannot fit: at most {most} in signals of {n} frames", count.target_count),
            );
        }
        let width = count.smoothing_frames;
        if width == 0 || width % 2 == 0 || width > n {
            self.inconsistent(
                field(path, "smoothing_frames"),
                format!("must be odd and between 1 and the signal length {n}; got {width}"),
            );
        }
        self.frames(&field(path, "frames"), &count.frames, n);
    }

    fn events(&mut self, path: &str, e: &Events) {
        let at = field(path, "signal");
        let n = self.scalar(&at, &e.signal);
        let limit = e.signal.unit().absurd_limit();
        let unit = unit_name(&e.signal);
        let (name, threshold) = match e.event {
            EventRegion::Below(v) => ("below", v),
            EventRegion::Above(v) => ("above", v),
        };
        self.number(&field(&field(path, "event"), name), threshold, -limit, limit, unit);
        if let Some(h) = e.hysteresis {
            let at = field(path, "hysteresis");
            if self.number(&at, h, 0.0, limit, unit) && h == 0.0 {
                self.inconsistent(at, "a hysteresis of 0 counts every wobble across the threshold");
            }
        }
        let Some(n) = n else { return };
        // An event and the way back out of it take at least two frames each.
        let most = n.div_ceil(2);
        if e.target_count > most {
            self.inconsistent(
                field(path, "target_count"),
                format!("{} events cannot fit: at most {most} in a signal of {n} frames", e.target_count),
            );
        }
        self.frames(&field(path, "frames"), &e.frames, n);
    }

    fn airborne(&mut self, path: &str, e: &Airborne) {
        self.number(&field(path, "clearance_m"), e.clearance_m, 0.0, MAX_ABS_M, "m");
        self.frames(&field(path, "frames"), &e.frames, self.frames);
        if let Some(when) = &e.when {
            self.condition(&field(path, "when"), when);
        }
        let at = field(path, "min_frames");
        if e.min_frames == 0 {
            self.inconsistent(at, "a flight of 0 frames is no flight");
        } else if let Some(longest) = longest_run(&e.frames, self.frames) {
            if e.min_frames > longest {
                self.inconsistent(
                    at,
                    format!(
                        "{} consecutive frames do not fit: the longest run of selected frames is {longest}",
                        e.min_frames
                    ),
                );
            }
        }
    }

    fn primitive(&mut self, path: &str, primitive: &Primitive) {
        let at = |name: &str| field(path, name);
        match primitive {
            Primitive::Gap(gap) => {
                self.number(&at("centre_x_m"), gap.centre_x_m, -MAX_ABS_M, MAX_ABS_M, "m");
                let width = self.number(&at("width_m"), gap.width_m, 0.0, MAX_ABS_M, "m");
                let margin = self.number(&at("margin_m"), gap.margin_m, 0.0, MAX_ABS_M, "m");
                if width && margin && gap.width_m <= 2.0 * gap.margin_m {
                    self.inconsistent(
                        at("width_m"),
                        format!(
                            "a gap {} m wide leaves no room with a {} m margin on each wall",
                            gap.width_m, gap.margin_m
                        ),
                    );
                }
                if let Some(range) = &gap.z_range_m {
                    self.interval_m(&at("z_range_m"), range);
                }
            }
            Primitive::OverheadBarrier(barrier) => {
                let h = self.number(&at("underside_height_m"), barrier.underside_height_m, 0.0, MAX_ABS_M, "m");
                let m = self.number(&at("margin_m"), barrier.margin_m, 0.0, MAX_ABS_M, "m");
                if h && m && barrier.margin_m >= barrier.underside_height_m {
                    self.inconsistent(at("margin_m"), "the margin leaves no room under the barrier");
                }
                self.interval_m(&at("z_range_m"), &barrier.z_range_m);
                if let Some(range) = &barrier.x_range_m {
                    self.interval_m(&at("x_range_m"), range);
                }
            }
            Primitive::Hurdle(hurdle) => {
                self.number(&at("height_m"), hurdle.height_m, 0.0, MAX_ABS_M, "m");
                self.number(&at("margin_m"), hurdle.margin_m, 0.0, MAX_ABS_M, "m");
                self.interval_m(&at("z_range_m"), &hurdle.z_range_m);
                if let Some(range) = &hurdle.x_range_m {
                    self.interval_m(&at("x_range_m"), range);
                }
            }
            Primitive::Ground(ground) => {
                self.number(&at("height_m"), ground.height_m, -MAX_ABS_M, MAX_ABS_M, "m");
            }
            Primitive::InsideBox(b) => {
                let ranges = [("x_range_m", &b.x_range_m), ("y_range_m", &b.y_range_m), ("z_range_m", &b.z_range_m)];
                if ranges.iter().all(|(_, range)| range.is_none()) {
                    self.inconsistent(path, "a box needs at least one of x_range_m, y_range_m, z_range_m");
                }
                for (name, range) in ranges {
                    if let Some(range) = range {
                        self.interval_m(&at(name), range);
                    }
                }
            }
            Primitive::Wall(wall) => {
                self.point_m(&at("point_m"), &wall.point_m);
                self.direction(&at("normal"), &wall.normal);
                self.number(&at("margin_m"), wall.margin_m, 0.0, MAX_ABS_M, "m");
            }
            Primitive::BalanceBeam(beam) => {
                self.point_m(&at("point_m"), &beam.point_m);
                self.direction(&at("direction"), &beam.direction);
                self.number(&at("half_width_m"), beam.half_width_m, 0.0, MAX_ABS_M, "m");
                let [dx, _, dz] = beam.direction;
                if beam.horizontal && beam.direction.iter().all(|v| v.is_finite()) && dx.hypot(dz) < 1e-6 {
                    self.inconsistent(at("direction"), "a horizontal beam needs a direction with an x or z part");
                }
                if let Some(range) = &beam.extent_m {
                    self.interval_m(&at("extent_m"), range);
                }
            }
        }
    }

    fn foot_contact(&mut self, path: &str, e: &FootContact) {
        const FEET: [Joint; 4] = [Joint::LeftAnkle, Joint::RightAnkle, Joint::LeftFoot, Joint::RightFoot];
        let feet = field(path, "feet");
        for (i, joint) in e.feet.iter().enumerate() {
            if !FEET.contains(joint) {
                self.inconsistent(
                    index(&feet, i),
                    format!("`{}` is not a foot joint (left_ankle, right_ankle, left_foot, right_foot)", joint.name()),
                );
            }
        }
        self.distinct_joints(&feet, &e.feet);
        for (i, frame) in e.at.iter().enumerate() {
            self.frame_ref(&index(&field(path, "at"), i), *frame, self.frames);
        }
        match &e.during {
            Some(range) => self.frame_range(&field(path, "during"), range, self.frames),
            None if e.at.is_empty() => {
                self.inconsistent(path, "give the contact frames: `at` (single frames), `during` (a range) or both")
            }
            None => {}
        }
        self.number(&field(path, "max_height_m"), e.max_height_m, 0.0, MAX_ABS_M, "m");
        if let Some(speed) = e.max_speed_m_per_s {
            self.number(&field(path, "max_speed_m_per_s"), speed, 0.0, MAX_ABS_M, "m/s");
        }
    }

    fn self_collision(&mut self, path: &str, e: &SelfCollision) {
        let torso = field(path, "torso");
        for (i, joint) in e.torso.iter().enumerate() {
            if e.limbs.contains(joint) {
                self.inconsistent(index(&torso, i), format!("`{}` is also a limb", joint.name()));
            }
        }
        self.distinct_joints(&field(path, "limbs"), &e.limbs);
        self.distinct_joints(&torso, &e.torso);
        self.number(&field(path, "min_distance_m"), e.min_distance_m, 0.0, MAX_ABS_M, "m");
        self.frames(&field(path, "frames"), &e.frames, self.frames);
    }
}

/// The most consecutive frames a selection keeps in a clip of `n` frames; `None` when a frame
/// of it lies outside (reported by the frame checks).
fn longest_run(selection: &FrameSelection, n: u32) -> Option<u32> {
    let mut kept: Vec<u32> = match selection {
        FrameSelection::All => return Some(n),
        FrameSelection::Keyframes(keys) => keys.iter().map(|k| k.resolve(n)).collect::<Option<_>>()?,
        FrameSelection::Range(range) => {
            let (from, to) = (range.from.resolve(n)?, range.to.resolve(n)?);
            return Some((to + 1).saturating_sub(from));
        }
    };
    kept.sort_unstable();
    kept.dedup();
    let (mut best, mut run) = (0, 0);
    for (i, f) in kept.iter().enumerate() {
        run = if i > 0 && kept[i - 1] + 1 == *f { run + 1 } else { 1 };
        best = best.max(run);
    }
    Some(best)
}

fn unit_name(quantity: &Quantity) -> &'static str {
    quantity.unit().symbol()
}
