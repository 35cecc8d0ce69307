//! Fanuc TP programs as text (`.ls`): the positions of the `/POS` section, group 1 (the robot).
//!
//! ```text
//! P[3:"pick"]{
//!    GP1:
//!     UF : 1, UT : 2,        CONFIG : 'N U T, 0, 0, 0',
//!     X =   512.340  mm,    Y =  -120.000  mm,    Z =   300.125  mm,
//!     W =   180.000 deg,    P =     0.000 deg,    R =    90.000 deg
//! };
//! P[4]{
//!    GP1:
//!     UF : 0, UT : 2,
//!     J1=    10.000 deg,    J2=   -20.000 deg,    J3=    30.000 deg,
//!     J4=     0.000 deg,    J5=   -45.000 deg,    J6=     0.000 deg
//! };
//! ```
//!
//! A Cartesian position is the TCP of tool `UT` in user frame `UF` (mm; W, P, R deg: rotations
//! about the fixed x, y, z axes, the rotation `Rz(R)·Ry(P)·Rx(W)`). `UF` and `UT` frames are not
//! in the program: they are given by number (`--uframe n:x,y,z,w,p,r`, `--utool n:…`); 0 is the
//! world and the faceplate. `CONFIG : 'F|N U|D T|B, t4, t5, t6'` picks the solution — F (flip)
//! axis 5 negative, D (down) the wrist centre behind the lower arm (the elbow's other side),
//! B (back) the wrist centre behind axis 1, and the turn numbers of axes 4, 5, 6 (turn n: the axis
//! in [−180° + n·360°, 180° + n·360°)) — and is written for the compensated joints. Cartesian
//! numbers are written with three decimals, right-aligned in the field they had, as the controller
//! writes them (0.5 µm per coordinate); joint values with five (three would lose up to 0.0005° per
//! joint, micrometres at the TCP). Joint values are the model's joints (Fanuc's J2/J3 coupling is not modelled: the robot
//! model must use the controller's joint convention). Other motion groups and everything outside
//! `/POS` are kept as they are. A position that cannot be compensated gets the comment
//! `NOT COMPENSATED` in its own comment field (`P[4:"NOT COMPENSATED"]`).

use super::lex::{self, Edit, Lines};
use super::{
    Dialect, FanucComment, Kind, Parsed, Posture, ProgramError, ProgramFile, Ref, Solution, Style, Target, frame_mm_deg,
};
use crate::domain::pose::zyx_deg_near;
use crate::kinematics::{Branch, Frame, Tool};
use crate::units::{DEG, MM};

pub(crate) struct Fanuc;

/// Decimals of the joint values written: the controller writes three (0.0005°, up to ~5 µm at the
/// TCP of a 1 m arm, more than the correction's last micrometres); five (0.00001°) are within a
/// 32-bit REAL's resolution at 360°.
const JOINT_DECIMALS: usize = 5;

/// A byte cursor over one file.
struct Cursor<'a> {
    file: &'a str,
    bytes: &'a [u8],
    at: usize,
    lines: &'a Lines,
}

impl Cursor<'_> {
    fn skip_ws(&mut self) {
        while self.at < self.bytes.len() && self.bytes[self.at].is_ascii_whitespace() {
            self.at += 1;
        }
    }

    fn peek(&self) -> Option<u8> {
        self.bytes.get(self.at).copied()
    }

    fn err(&self, msg: impl Into<String>) -> ProgramError {
        ProgramError::new(self.file, self.lines.line_of(self.at.min(self.bytes.len().saturating_sub(1))), msg)
    }

    fn starts_with(&self, s: &[u8]) -> bool {
        self.bytes[self.at..].len() >= s.len() && self.bytes[self.at..self.at + s.len()].eq_ignore_ascii_case(s)
    }

    fn expect(&mut self, s: &[u8]) -> Result<(), ProgramError> {
        self.skip_ws();
        if self.starts_with(s) {
            self.at += s.len();
            Ok(())
        } else {
            let found: String = lex::latin1(&self.bytes[self.at..(self.at + 12).min(self.bytes.len())]);
            Err(self.err(format!("expected '{}', found '{}'", lex::latin1(s), found.trim_end())))
        }
    }

    fn word(&mut self) -> String {
        self.skip_ws();
        let s = self.at;
        while self.at < self.bytes.len() && (self.bytes[self.at].is_ascii_alphanumeric() || self.bytes[self.at] == b'_')
        {
            self.at += 1;
        }
        lex::latin1(&self.bytes[s..self.at]).to_ascii_uppercase()
    }

    /// A signed number after optional spaces: (span including the spaces before it, value).
    fn number(&mut self) -> Result<((usize, usize), f64), ProgramError> {
        let from = self.at;
        self.skip_ws();
        let s = self.at;
        if matches!(self.peek(), Some(b'-' | b'+')) {
            self.at += 1;
        }
        let e = lex::number_end(self.bytes, self.at);
        let value = lex::number(&self.bytes[s..e]).ok_or_else(|| self.err("expected a number"))?;
        self.at = e;
        Ok(((from, e), value))
    }
}

/// One field of a group: name, and its value.
enum Field {
    Number { span: (usize, usize), value: f64, unit: String },
    Config { span: (usize, usize), text: String },
    Other,
}

impl Dialect for Fanuc {
    fn parse(&self, files: &[ProgramFile]) -> Result<Parsed, ProgramError> {
        let mut parsed = Parsed::default();
        for (fi, f) in files.iter().enumerate() {
            let lines = Lines::new(&f.bytes);
            let Some(start) = section(&f.bytes, b"/POS") else {
                if section(&f.bytes, b"/PROG").is_none() {
                    return Err(ProgramError::new(&f.name, 1, "not a Fanuc TP program: no /PROG line"));
                }
                continue; // no positions
            };
            let end = section(&f.bytes, b"/END").filter(|e| *e > start).unwrap_or(f.bytes.len());
            let mut c = Cursor { file: &f.name, bytes: &f.bytes[..end], at: start + 4, lines: &lines };
            // The positions of this file by name → line (a name defined twice is refused).
            let mut seen = std::collections::HashMap::new();
            loop {
                c.skip_ws();
                if c.at >= end {
                    break;
                }
                position(&mut c, fi, &mut parsed, &mut seen)?;
            }
            if section(&f.bytes, b"/END").is_none() {
                return Err(ProgramError::new(
                    &f.name,
                    lines.line_of(f.bytes.len().saturating_sub(1)),
                    "the program has no /END line",
                ));
            }
            if let Some(mn) = section(&f.bytes, b"/MN").filter(|m| *m < start) {
                motion_order(&f.bytes[mn + 3..start], fi, &mut parsed);
            }
        }
        Ok(parsed)
    }

    fn render(&self, t: &Target, s: &Solution) -> Vec<Edit> {
        let field = |slot: (usize, usize), v: f64, decimals: usize| {
            let width = slot.1 - slot.0;
            let mut text = format!("{v:.decimals$}");
            if text.starts_with('-') && text[1..].bytes().all(|b| b == b'0' || b == b'.') {
                text.remove(0);
            }
            Edit::replace(slot, format!(" {text:>w$}", w = width.saturating_sub(1)))
        };
        let mut out = Vec::with_capacity(t.slots.len() + 1);
        match &t.kind {
            Kind::Pose { .. } => {
                let pose = s.pose.expect("a pose target's solution has a pose");
                for k in 0..3 {
                    out.push(field(t.slots[k], pose.t[k] / MM, 3));
                }
                // W, P, R = c, b, a of ZY'X''.
                let hint = [t.values[5], t.values[4], t.values[3]];
                let [a, b, cc] = zyx_deg_near(&pose.r, hint);
                for (k, v) in [cc, b, a].into_iter().enumerate() {
                    out.push(field(t.slots[3 + k], v, 3));
                }
                if let (Style::Fanuc { config: Some(span), .. }, Some(cd)) = (&t.style, s.confdata) {
                    let b = cd.cfx;
                    let turn = |q: f64| ((q + std::f64::consts::PI) / std::f64::consts::TAU).floor() as i64;
                    let text = format!(
                        "{} {} {}, {}, {}, {}",
                        if b.wrist_negative() { 'F' } else { 'N' },
                        if b.elbow_behind() { 'D' } else { 'U' },
                        if b.shoulder_back() { 'B' } else { 'T' },
                        turn(s.joints[3]),
                        turn(s.joints[4]),
                        turn(s.joints[5])
                    );
                    out.push(Edit::replace(*span, text));
                }
            }
            Kind::Joints { .. } => {
                for (k, q) in s.joints.iter().enumerate().take(t.slots.len()) {
                    out.push(field(t.slots[k], q / DEG, JOINT_DECIMALS));
                }
            }
        }
        out
    }

    fn mark(&self, _bytes: &[u8], _lines: &Lines, t: &Target, _why: &str) -> Edit {
        match &t.style {
            Style::Fanuc { comment: FanucComment::None { close }, .. } => Edit::insert(*close, ":\"NOT COMPENSATED\""),
            Style::Fanuc { comment: FanucComment::Text { start }, .. } => Edit::insert(*start, "NOT COMPENSATED "),
            _ => unreachable!("Fanuc targets carry a Fanuc style"),
        }
    }
}

/// The positions the `/MN` motions use, in their order (`J P[1] …`, `L P[2] …`, `C P[3] : P[4] …`,
/// `A P[5] …`; position registers `PR[n]` and comments are not positions): the program's
/// [`Parsed::sequence`]. Only what a reader of the program needs (Fanuc positions carry their
/// configuration, so the filter's seeds do not depend on it); a position no `/POS` entry defines
/// is skipped.
fn motion_order(mn: &[u8], fi: usize, parsed: &mut Parsed) {
    let text = lex::latin1(mn);
    let index: std::collections::HashMap<&str, usize> =
        parsed.targets.iter().enumerate().filter(|(_, t)| t.file == fi).map(|(i, t)| (t.name.as_str(), i)).collect();
    let mut order = Vec::new();
    // A circular motion's end point is on the next line, numbered with spaces (`    :  P[4] …`).
    let mut circle_end = false;
    for line in text.lines() {
        // `  12:L P[3] 500mm/sec FINE ;`: the line number, then the instruction.
        let Some((number, body)) = line.split_once(':') else { continue };
        let number = number.trim();
        let b = body.as_bytes();
        let from = if number.is_empty() && std::mem::take(&mut circle_end) {
            0
        } else if !number.is_empty()
            && number.bytes().all(|c| c.is_ascii_digit())
            && b.len() > 2
            && matches!(b[0].to_ascii_uppercase(), b'J' | b'L' | b'C' | b'A')
            && b[1].is_ascii_whitespace()
        {
            circle_end = b[0].eq_ignore_ascii_case(&b'C');
            1
        } else {
            circle_end = false;
            continue;
        };
        let mut at = from;
        while let Some(p) = body[at..].find("P[") {
            let k = at + p;
            at = k + 2;
            if k > 0 && (b[k - 1].is_ascii_alphanumeric() || b[k - 1] == b'_') {
                continue; // PR[n], a register
            }
            let digits: String = body[k + 2..].chars().take_while(char::is_ascii_digit).collect();
            if let Ok(n) = digits.parse::<u64>()
                && let Some(&i) = index.get(format!("P[{n}]").as_str())
            {
                order.push(i);
            }
        }
    }
    parsed.sequence.extend(order);
}

/// The offset of a line starting with `tag` (`/POS`, `/END`).
fn section(bytes: &[u8], tag: &[u8]) -> Option<usize> {
    let mut at = 0;
    while at < bytes.len() {
        let line_end = bytes[at..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |p| at + p);
        let mut s = at;
        while s < line_end && (bytes[s] == b' ' || bytes[s] == b'\t') {
            s += 1;
        }
        if bytes[s..line_end].len() >= tag.len() && bytes[s..s + tag.len()].eq_ignore_ascii_case(tag) {
            let next = bytes.get(s + tag.len()).copied();
            if next.is_none_or(|b| !b.is_ascii_alphanumeric()) {
                return Some(s);
            }
        }
        at = line_end + 1;
    }
    None
}

/// One `P[n…]{ … };` at the cursor.
fn position(
    c: &mut Cursor,
    fi: usize,
    parsed: &mut Parsed,
    seen: &mut std::collections::HashMap<String, usize>,
) -> Result<(), ProgramError> {
    c.skip_ws();
    let begin = c.at;
    let line = c.lines.line_of(begin);
    c.expect(b"P[")?;
    let (_, n) = c.number()?;
    if n.fract() != 0.0 || n < 0.0 {
        return Err(c.err("a position number must be a whole number"));
    }
    let name = format!("P[{}]", n as i64);
    c.skip_ws();
    let comment = if c.peek() == Some(b':') {
        c.at += 1;
        c.skip_ws();
        if c.peek() != Some(b'"') {
            return Err(c.err(format!("{name}: expected a quoted comment after ':'")));
        }
        let start = c.at + 1;
        let close = c.bytes[start..].iter().position(|&b| b == b'"' || b == b'\n').map(|p| start + p);
        match close {
            Some(q) if c.bytes[q] == b'"' => c.at = q + 1,
            _ => return Err(c.err(format!("{name}: its comment is not closed"))),
        }
        FanucComment::Text { start }
    } else {
        FanucComment::None { close: c.at }
    };
    c.expect(b"]")?;
    c.expect(b"{")?;
    let mut gp1: Option<(Vec<(String, Field)>, usize)> = None;
    loop {
        c.skip_ws();
        if c.starts_with(b"}") {
            c.at += 1;
            c.expect(b";")?;
            break;
        }
        if c.at >= c.bytes.len() {
            return Err(ProgramError::new(c.file, line, format!("{name}: not closed by '}};'")));
        }
        let group_line = c.lines.line_of(c.at);
        let g = c.word();
        if !g.starts_with("GP") || g.len() < 3 {
            return Err(c.err(format!("{name}: expected a group (GP1:), found '{g}'")));
        }
        c.expect(b":")?;
        let fields = fields(c, &name)?;
        if g == "GP1" {
            gp1 = Some((fields, group_line));
        }
    }
    let extent_end = c.at;
    let Some((fields, gline)) = gp1 else {
        return Err(ProgramError::new(c.file, line, format!("{name}: no GP1 group")));
    };
    if let Some(first) = seen.insert(name.clone(), line) {
        return Err(ProgramError::new(c.file, line, format!("{name} is defined twice (lines {first} and {line})")));
    }
    let get = |k: &str| fields.iter().find(|(n, _)| n == k).map(|(_, f)| f);
    let int = |k: &str| match get(k) {
        Some(Field::Number { value, .. }) if value.fract() == 0.0 && *value >= 0.0 => Ok(format!("{}", *value as i64)),
        Some(_) => Err(format!("{k} must be a frame number")),
        None => Err(format!("{k} is missing")),
    };
    let mut t = Target {
        file: fi,
        name: name.clone(),
        line,
        kind: Kind::Joints { q: Vec::new() },
        tool: match int("UT") {
            Ok(n) if n == "0" => Ref::Given(Tool::flange()),
            Ok(n) => Ref::Named(n),
            Err(e) => Ref::Missing(e),
        },
        payload: None,
        base: match int("UF") {
            Ok(n) if n == "0" => Ref::Given(Frame::identity()),
            Ok(n) => Ref::Named(n),
            Err(e) => Ref::Missing(e),
        },
        slots: Vec::new(),
        values: Vec::new(),
        extent: (begin, extent_end),
        problem: None,
        notes: Vec::new(),
        style: Style::Fanuc { config: None, comment },
    };
    let num = |k: &str, unit: &str| -> Result<((usize, usize), f64), ProgramError> {
        match get(k) {
            Some(Field::Number { span, value, unit: u }) if u.eq_ignore_ascii_case(unit) => Ok((*span, *value)),
            Some(Field::Number { unit: u, .. }) => {
                Err(ProgramError::new(c.file, gline, format!("{name}: {k} is in '{u}', expected {unit}")))
            }
            _ => Err(ProgramError::new(c.file, gline, format!("{name}: {k} is missing"))),
        }
    };
    if get("X").is_some() {
        for (k, u) in [("X", "mm"), ("Y", "mm"), ("Z", "mm"), ("W", "deg"), ("P", "deg"), ("R", "deg")] {
            let (span, v) = num(k, u)?;
            t.slots.push(span);
            t.values.push(v);
        }
        let v = &t.values;
        let pose = frame_mm_deg([v[0], v[1], v[2]], [v[5], v[4], v[3]]);
        let posture = match get("CONFIG") {
            Some(Field::Config { span, text }) => {
                t.style = Style::Fanuc { config: Some(*span), comment };
                config(text).map_err(|e| ProgramError::new(c.file, gline, format!("{name}: CONFIG '{text}': {e}")))?
            }
            _ => return Err(ProgramError::new(c.file, gline, format!("{name}: CONFIG is missing"))),
        };
        t.kind = Kind::Pose { pose, posture };
    } else if get("J1").is_some() {
        for j in 1..=6 {
            let (span, v) = num(&format!("J{j}"), "deg")?;
            t.slots.push(span);
            t.values.push(v);
        }
        t.kind = Kind::Joints { q: t.values.iter().map(|v| v * DEG).collect() };
    } else {
        return Err(ProgramError::new(c.file, gline, format!("{name}: GP1 has neither X, Y, Z, W, P, R nor J1…J6")));
    }
    parsed.targets.push(t);
    Ok(())
}

/// A group's fields up to the next group or the closing `}`.
fn fields(c: &mut Cursor, name: &str) -> Result<Vec<(String, Field)>, ProgramError> {
    let mut out = Vec::new();
    loop {
        c.skip_ws();
        if c.starts_with(b"}") || c.at >= c.bytes.len() {
            return Ok(out);
        }
        let save = c.at;
        let key = c.word();
        if key.is_empty() {
            return Err(c.err(format!("{name}: expected a field name")));
        }
        c.skip_ws();
        if key.starts_with("GP") && key[2..].bytes().all(|b| b.is_ascii_digit()) && c.peek() == Some(b':') {
            c.at = save;
            return Ok(out);
        }
        match c.peek() {
            Some(b':' | b'=') => c.at += 1,
            _ => {
                let line = c.lines.line_of(save);
                return Err(ProgramError::new(c.file, line, format!("{name}: expected ':' or '=' after {key}")));
            }
        }
        let eq = c.at;
        c.skip_ws();
        let field = if c.peek() == Some(b'\'') {
            let start = c.at + 1;
            let close = c.bytes[start..].iter().position(|&b| b == b'\'' || b == b'\n').map(|p| start + p);
            match close {
                Some(q) if c.bytes[q] == b'\'' => {
                    c.at = q + 1;
                    Field::Config { span: (start, q), text: lex::latin1(&c.bytes[start..q]) }
                }
                _ => return Err(c.err(format!("{name}: {key}: the quoted value is not closed"))),
            }
        } else if matches!(c.peek(), Some(b'-' | b'+' | b'.' | b'0'..=b'9')) {
            c.at = eq;
            let (span, value) = c.number()?;
            let save = c.at;
            let unit = c.word();
            let unit = if unit == "MM" || unit == "DEG" {
                unit.to_ascii_lowercase()
            } else {
                c.at = save;
                String::new()
            };
            Field::Number { span, value, unit }
        } else {
            let w = c.word();
            if w.is_empty() {
                return Err(c.err(format!("{name}: {key} has no value")));
            }
            Field::Other
        };
        out.push((key, field));
        c.skip_ws();
        if c.peek() == Some(b',') {
            c.at += 1;
        }
    }
}

/// `'N U T, 0, 0, 0'` → the branch and the turn ranges of axes 4, 5, 6.
fn config(text: &str) -> Result<Posture, String> {
    let mut parts = text.split(',');
    let letters: Vec<char> =
        parts.next().unwrap_or_default().split_whitespace().filter_map(|w| w.chars().next()).collect();
    if letters.len() != 3 {
        return Err("expected three letters (F|N U|D T|B)".into());
    }
    let flag = |c: char, yes: char, no: char| match c.to_ascii_uppercase() {
        x if x == yes => Ok(true),
        x if x == no => Ok(false),
        _ => Err(format!("'{c}' is not {yes} or {no}")),
    };
    let wrist = flag(letters[0], 'F', 'N')?;
    let elbow = flag(letters[1], 'D', 'U')?;
    let shoulder = flag(letters[2], 'B', 'T')?;
    let turns: Vec<i64> = parts
        .map(|p| p.trim().parse::<i64>().map_err(|_| format!("'{}' is not a turn number", p.trim())))
        .collect::<Result<_, _>>()?;
    if turns.len() != 3 || turns.iter().any(|t| t.abs() > 8) {
        return Err("expected three turn numbers (axes 4, 5, 6)".into());
    }
    let pi = std::f64::consts::PI;
    let range = |n: i64| Some((-pi + n as f64 * 2.0 * pi, pi + n as f64 * 2.0 * pi));
    Ok(Posture::Turns {
        branch: Branch::from_flags(shoulder, elbow, wrist),
        ranges: [None, None, None, range(turns[0]), range(turns[1]), range(turns[2])],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::program::{FilterError, FilterOptions, read};

    const LS: &str = "/PROG  WELD\n/ATTR\nCOMMENT = \"X = 100 mm\";\n/MN\n   1:  UFRAME_NUM=1 ;\n   2:J P[1] 100% FINE    ;\n   3:  !P[1] X = 5 mm ;\n/POS\nP[1]{\n   GP1:\n\tUF : 1, UT : 2,\t\tCONFIG : 'F D B, 0, 0, -1',\n\tX =   512.340  mm,\tY =  -120.000  mm,\tZ =   300.125  mm,\n\tW =   180.000 deg,\tP =     0.000 deg,\tR =    90.000 deg\n   GP2:\n\tUF : 1, UT : 2,\t\n\tJ1=     0.000  mm\n};\nP[2:\"home\"]{\n   GP1:\n\tUF : 0, UT : 0,\t\n\tJ1=    10.000 deg,\tJ2=   -20.000 deg,\tJ3=    30.000 deg,\n\tJ4=     0.000 deg,\tJ5=   -45.000 deg,\tJ6=     0.000 deg\n};\n/END\n";

    #[test]
    fn positions_are_read_with_their_frames_and_configuration() {
        let files = vec![ProgramFile { name: "weld.ls".into(), bytes: LS.as_bytes().to_vec() }];
        let (_, t) = read(&files, &FilterOptions::default()).unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!((t[0].name.as_str(), t[0].line), ("P[1]", 9));
        // F D B: axis 5 negative, behind the lower arm, behind axis 1.
        assert_eq!(t[0].branch, Some(Branch::from_flags(true, true, true)));
        let r6 = t[0].ranges[5].unwrap();
        assert!((r6.0 + 3.0 * std::f64::consts::PI).abs() < 1e-12);
        let p = t[0].pose.unwrap();
        assert!((p.t.x - 0.51234).abs() < 1e-15);
        // W 180, P 0, R 90: Rz(90°)·Rx(180°).
        let want = crate::kinematics::frame::rot_zyx(90.0 * DEG, 0.0, 180.0 * DEG);
        assert!((p.r - want).abs().max() < 1e-15);
        assert!(t[0].tool.as_ref().unwrap_err().contains("'2'"));
        assert_eq!(t[1].joints.as_ref().unwrap()[4], -45.0 * DEG);
        assert_eq!(t[1].tool.clone().unwrap(), Tool::flange());
    }

    #[test]
    fn the_motions_give_the_order_of_the_positions() {
        use crate::domain::program::motion_order;
        let mn = "/MN\n   1:J P[2:\"home\"] 100% FINE    ;\n   2:  !P[1] X = 5 mm ;\n   3:L P[1] 500mm/sec CNT100 Offset,PR[2]    ;\n   4:C P[1]    \n    :  P[2] 100mm/sec FINE    ;\n   5:  CALL SUB_P[1] ;\n   6:J P[7] 100% FINE ;\n/POS\n";
        let ls =
            LS.replace("/MN\n   1:  UFRAME_NUM=1 ;\n   2:J P[1] 100% FINE    ;\n   3:  !P[1] X = 5 mm ;\n/POS\n", mn);
        assert_ne!(ls, LS);
        let files = vec![ProgramFile { name: "weld.ls".into(), bytes: ls.into_bytes() }];
        // P[2] is target 1, P[1] target 0; the circle's end point is on its continuation line; the
        // comment, the register, the call and the undefined P[7] are not motions to positions.
        assert_eq!(motion_order(&files, None).unwrap(), vec![1, 0, 0, 1]);
    }

    #[test]
    fn malformed_positions_name_their_line() {
        let bad = LS.replace("\tY =  -120.000  mm,", "\tY =  -120.000  mm");
        let bad = bad.replace("Z =   300.125  mm", "Z =   300.125  mm, Q");
        let files = vec![ProgramFile { name: "weld.ls".into(), bytes: bad.into_bytes() }];
        match read(&files, &FilterOptions::default()) {
            Err(FilterError::Program(e)) => assert_eq!(e.line, 12, "{e}"),
            other => panic!("{other:?}"),
        }
        let bad = LS.replace("CONFIG : 'F D B, 0, 0, -1'", "CONFIG : 'F X B, 0, 0, -1'");
        let files = vec![ProgramFile { name: "weld.ls".into(), bytes: bad.into_bytes() }];
        match read(&files, &FilterOptions::default()) {
            Err(FilterError::Program(e)) => assert!(e.line == 10 && e.message.contains("'X'"), "{e}"),
            other => panic!("{other:?}"),
        }
        // A position number used twice: P[2:"home"] (line 18) renumbered as P[1] (line 9).
        let bad = LS.replace("P[2:\"home\"]", "P[1:\"home\"]");
        let files = vec![ProgramFile { name: "weld.ls".into(), bytes: bad.into_bytes() }];
        match read(&files, &FilterOptions::default()) {
            Err(FilterError::Program(e)) => {
                assert_eq!((e.line, e.message.as_str()), (18, "P[1] is defined twice (lines 9 and 18)"), "{e}")
            }
            other => panic!("{other:?}"),
        }
    }
}
