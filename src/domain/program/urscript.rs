//! Universal Robots URScript: the poses and joint positions motions go to.
//!
//! ```text
//! set_tcp(p[0.0, 0.0, 0.15, 0.0, 0.0, 0.0])
//! set_payload(1.2, [0.0, 0.0, 0.05])
//! approach = p[0.5, -0.2, 0.4, 0.0, 3.1416, 0.0]
//! movej([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], a=1.4, v=1.05)
//! movel(approach, a=1.2, v=0.25)
//! movel(p[0.5, -0.2, 0.3, 0.0, 3.1416, 0.0], a=1.2, v=0.1)
//! ```
//!
//! Targets: pose literals `p[x, y, z, rx, ry, rz]` (metres; rotation vector, rad) written as the
//! first argument of `movel`, `movej`, `movep` (both points of `movec`), or assigned to a variable
//! (`name = p[…]`, `global`/`local` too) that a motion uses; joint positions `[q1, …, q6]` (rad) in
//! `movej`, `movel` or a variable a motion uses. Poses are in the robot's base frame. The TCP is the
//! last `set_tcp(p[…])` before the motion (or, without one, the tool given as `tcp`), the payload
//! the last `set_payload(m, [cx, cy, cz])`. A pose carries no configuration: the controller takes
//! the solution nearest the joints it is at, so each pose is solved from the motion before it (the
//! first one from the given starting joints, or the `movej([…])` before it). A literal passed to
//! another function (`pose_trans(p[…], …)`, `get_inverse_kin(p[…])`) is an offset or a computation,
//! not a target, and is left alone. Failures are marked `# robocal: NOT COMPENSATED: …`.

use std::collections::HashMap;

use nalgebra::{Rotation3, Vector3};

use super::lex::{self, Edit, Lines, Syntax, Tok, Token};
use super::{Dialect, Kind, Parsed, Posture, ProgramError, ProgramFile, Ref, Solution, Style, Target, tool_of};
use crate::kinematics::Frame;
use crate::kinematics::frame::rotation_vector;

const SYNTAX: Syntax = Syntax { comment: b'#', ident_extra: &[], quotes: b"\"'" };
const MOTIONS: &[&str] = &["movel", "movej", "movep", "movec"];

pub(crate) struct UrScript;

/// A literal list `[n, …]` or `p[n, …]` at token `i`: its numbers (span, value), its extent, and
/// the token after it; `None` when it is not a list of literal numbers.
fn literal(toks: &[Token], bytes: &[u8], i: usize) -> Option<(lex::Literals, (usize, usize), usize)> {
    let mut k = i;
    let pose = toks.get(k)?.kind == Tok::Ident && toks[k].text(bytes) == b"p";
    if pose {
        k += 1;
    }
    let open = toks.get(k).filter(|t| t.is(b'['))?;
    k += 1;
    let mut out = Vec::new();
    loop {
        let s = k;
        if toks.get(k)?.is(b'-') || toks[k].is(b'+') {
            k += 1;
        }
        let t = toks.get(k).filter(|t| t.kind == Tok::Number)?;
        let span = (toks[s].start, t.end);
        out.push((span, lex::number(&bytes[span.0..span.1])?));
        k += 1;
        match toks.get(k)? {
            t if t.is(b',') => k += 1,
            t if t.is(b']') => {
                let start = if pose { toks[i].start } else { open.start };
                return Some((out, (start, t.end), k + 1));
            }
            _ => return None,
        }
    }
}

fn pose_frame(v: &[f64]) -> Frame {
    let r = Rotation3::new(Vector3::new(v[3], v[4], v[5]));
    Frame::new(*r.matrix(), Vector3::new(v[0], v[1], v[2]))
}

/// A variable's literal value, as assigned.
#[derive(Clone, Debug)]
struct Assigned {
    pose: bool,
    numbers: Vec<((usize, usize), f64)>,
    extent: (usize, usize),
    line: usize,
    name: String,
    /// The target it became, once a motion used it.
    target: Option<usize>,
}

impl Dialect for UrScript {
    fn parse(&self, files: &[ProgramFile]) -> Result<Parsed, ProgramError> {
        let mut parsed = Parsed::default();
        for (fi, f) in files.iter().enumerate() {
            let toks = lex::tokenize(&f.bytes, &SYNTAX, &f.name)?;
            let bytes = &f.bytes[..];
            let text = |i: usize| lex::latin1(toks[i].text(bytes));
            let mut tcp: Option<Result<Frame, String>> = None;
            let mut payload: Option<(f64, Vector3<f64>)> = None;
            let mut vars: HashMap<String, Assigned> = HashMap::new();
            let mut i = 0;
            while i < toks.len() {
                let t = toks[i];
                if t.kind != Tok::Ident {
                    i += 1;
                    continue;
                }
                let w = text(i);
                let call = toks.get(i + 1).is_some_and(|n| n.is(b'('));
                let after_dot = i > 0 && toks[i - 1].is(b'.');
                if w == "set_tcp" && call && !after_dot {
                    tcp = Some(match literal(&toks, bytes, i + 2) {
                        Some((v, _, next)) if v.len() == 6 && toks.get(next).is_some_and(|t| t.is(b')')) => {
                            Ok(pose_frame(&v.iter().map(|x| x.1).collect::<Vec<_>>()))
                        }
                        _ => Err(format!("the TCP is set by an expression (line {})", t.line)),
                    });
                    i += 2;
                } else if w == "set_payload" && call && !after_dot {
                    let mut k = i + 2;
                    let neg = toks.get(k).is_some_and(|t| t.is(b'-'));
                    if neg {
                        k += 1;
                    }
                    if let Some(m) =
                        toks.get(k).filter(|t| t.kind == Tok::Number).and_then(|t| lex::number(t.text(bytes)))
                    {
                        let com = if toks.get(k + 1).is_some_and(|t| t.is(b',')) {
                            literal(&toks, bytes, k + 2)
                                .filter(|(v, _, _)| v.len() == 3)
                                .map(|(v, _, _)| Vector3::new(v[0].1, v[1].1, v[2].1))
                        } else {
                            Some(Vector3::zeros())
                        };
                        if let Some(c) = com
                            && !neg
                        {
                            payload = Some((m, c));
                        }
                    }
                    i += 2;
                } else if MOTIONS.contains(&w.as_str()) && call && !after_dot {
                    let count = if w == "movec" { 2 } else { 1 };
                    let mut k = i + 2;
                    for n in 0..count {
                        if n > 0 {
                            if !toks.get(k).is_some_and(|t| t.is(b',')) {
                                break;
                            }
                            k += 1;
                        }
                        let tool = match &tcp {
                            None => Ref::Named("tcp".into()),
                            Some(Ok(f)) => Ref::Given(tool_of(f)),
                            Some(Err(e)) => Ref::Missing(e.clone()),
                        };
                        if let Some((v, extent, next)) = literal(&toks, bytes, k) {
                            let pose = toks[k].kind == Tok::Ident;
                            if !toks.get(next).is_some_and(|t| t.is(b',') || t.is(b')')) {
                                break; // an expression starting with a literal
                            }
                            let label = format!(
                                "{w} (inline{})",
                                if count == 2 { if n == 0 { ", via point" } else { ", end point" } } else { "" }
                            );
                            let a =
                                Assigned { pose, numbers: v, extent, line: toks[k].line, name: label, target: None };
                            let t = make_target(fi, &f.name, &a, tool, payload)?;
                            parsed.sequence.push(parsed.targets.len());
                            parsed.targets.push(t);
                            k = next;
                        } else if toks.get(k).is_some_and(|t| t.kind == Tok::Ident)
                            && toks.get(k + 1).is_some_and(|t| t.is(b',') || t.is(b')'))
                        {
                            let name = text(k);
                            if let Some(a) = vars.get_mut(&name) {
                                match a.target {
                                    Some(ti) => {
                                        let t: &mut Target = &mut parsed.targets[ti];
                                        if t.tool != tool || t.payload != payload {
                                            t.problem.get_or_insert(format!(
                                                "used with another TCP or payload on line {} than on line {}: one value cannot serve both",
                                                toks[k].line, t.line
                                            ));
                                        }
                                        parsed.sequence.push(ti);
                                    }
                                    None => {
                                        let t = make_target(fi, &f.name, a, tool, payload)?;
                                        a.target = Some(parsed.targets.len());
                                        parsed.sequence.push(parsed.targets.len());
                                        parsed.targets.push(t);
                                    }
                                }
                            }
                            k += 1;
                        } else {
                            break;
                        }
                    }
                    i += 2;
                } else if toks.get(i + 1).is_some_and(|n| n.is(b'='))
                    && !toks.get(i + 2).is_some_and(|n| n.is(b'='))
                    && !(i > 0
                        && (toks[i - 1].is(b'=')
                            || toks[i - 1].is(b'.')
                            || toks[i - 1].is(b'!')
                            || toks[i - 1].is(b'<')
                            || toks[i - 1].is(b'>')))
                {
                    // An assignment: a literal pose or joint list is a candidate target.
                    match literal(&toks, bytes, i + 2) {
                        Some((v, extent, next))
                            if v.len() == 6
                                && toks
                                    .get(next)
                                    .is_none_or(|n| n.line != toks[i].line || n.kind == Tok::Punct(b'#')) =>
                        {
                            let pose = toks[i + 2].kind == Tok::Ident;
                            vars.insert(
                                w.clone(),
                                Assigned { pose, numbers: v, extent, line: t.line, name: w.clone(), target: None },
                            );
                        }
                        _ => {
                            vars.remove(&w);
                        }
                    }
                    i += 2;
                } else {
                    i += 1;
                }
            }
        }
        Ok(parsed)
    }

    fn render(&self, t: &Target, s: &Solution) -> Vec<Edit> {
        let mut out = Vec::with_capacity(6);
        match &t.kind {
            Kind::Pose { .. } => {
                let pose = s.pose.expect("a pose target's solution has a pose");
                for k in 0..3 {
                    out.push(Edit::replace(t.slots[k], lex::trimmed(pose.t[k], 7)));
                }
                let v = rotation_vector(&pose.r);
                let hint = Vector3::new(t.values[3], t.values[4], t.values[5]);
                let angle = v.norm();
                let v = if angle > 1e-9 {
                    let other = v * (1.0 - std::f64::consts::TAU / angle);
                    if (other - hint).norm() < (v - hint).norm() { other } else { v }
                } else {
                    v
                };
                for k in 0..3 {
                    out.push(Edit::replace(t.slots[3 + k], lex::trimmed(v[k], 9)));
                }
            }
            Kind::Joints { .. } => {
                for (k, q) in s.joints.iter().enumerate().take(t.slots.len()) {
                    out.push(Edit::replace(t.slots[k], lex::trimmed(*q, 9)));
                }
            }
        }
        out
    }

    fn mark(&self, bytes: &[u8], lines: &Lines, t: &Target, why: &str) -> Edit {
        let at = lines.end_of_line(bytes, t.extent.1.saturating_sub(1));
        Edit::insert(at, format!("  # robocal: NOT COMPENSATED: {}", lex::comment_text(why, 240)))
    }
}

fn make_target(
    fi: usize,
    file: &str,
    a: &Assigned,
    tool: Ref<crate::kinematics::Tool>,
    payload: Option<(f64, Vector3<f64>)>,
) -> Result<Target, ProgramError> {
    if a.numbers.len() != 6 {
        return Err(ProgramError::new(
            file,
            a.line,
            format!(
                "{}: {} numbers; a {} has 6",
                a.name,
                a.numbers.len(),
                if a.pose { "pose p[x, y, z, rx, ry, rz]" } else { "joint position [q1, …, q6]" }
            ),
        ));
    }
    let values: Vec<f64> = a.numbers.iter().map(|x| x.1).collect();
    let kind = if a.pose {
        Kind::Pose { pose: pose_frame(&values), posture: Posture::Nearest }
    } else {
        Kind::Joints { q: values.clone() }
    };
    Ok(Target {
        file: fi,
        name: a.name.clone(),
        line: a.line,
        kind,
        tool,
        payload,
        base: Ref::Given(Frame::identity()),
        slots: a.numbers.iter().map(|x| x.0).collect(),
        values,
        extent: a.extent,
        problem: None,
        notes: Vec::new(),
        style: Style::Plain,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::program::{FilterError, FilterOptions, read};

    #[test]
    fn motions_variables_and_frames_are_read() {
        let text = "def prog():\n  set_tcp(p[0, 0, 0.15, 0, 0, 0])\n  set_payload(1.5, [0, 0, 0.05])\n  \
            global approach = p[0.5, -0.2, 0.4, 0, 3.3, 0]  # p[9, 9, 9, 9, 9, 9]\n  \
            feature = p[0.1, 0, 0, 0, 0, 0]\n  home = [0, -1.2, 1.3, -1.4, -1.5, 0]\n  \
            movej(home, a=1.4, v=1.05)\n  movel(approach, a=1.2, v=0.25)\n  \
            movel(pose_trans(feature, p[0, 0, 0.1, 0, 0, 0]), a=1, v=0.1)\n  \
            movec(p[0.5, 0, 0.3, 0, 3.14, 0], p[0.4, 0.1, 0.3, 0, 3.14, 0], a=1, v=0.1)\n  \
            textmsg(\"movel(p[1,2,3,4,5,6])\")\nend\n";
        let files = vec![ProgramFile { name: "prog.script".into(), bytes: text.as_bytes().to_vec() }];
        let (_, t) = read(&files, &FilterOptions::default()).unwrap();
        let names: Vec<&str> = t.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(names, ["home", "approach", "movec (inline, via point)", "movec (inline, end point)"]);
        assert_eq!(t[0].joints.as_ref().unwrap()[1], -1.2);
        assert_eq!(t[1].line, 4);
        let tool = t[1].tool.clone().unwrap();
        assert!((tool.tcp[2] - 0.15).abs() < 1e-15 && tool.mass == 1.5 && (tool.com.z - 0.05).abs() < 1e-15);
        let p = t[1].pose.unwrap();
        assert!((p.t - Vector3::new(0.5, -0.2, 0.4)).norm() < 1e-15);
        // A rotation vector of norm 3.3 > π: the same rotation as 2π − 3.3 about the opposite axis.
        assert!((crate::kinematics::frame::rotation_angle(&p.r) - (std::f64::consts::TAU - 3.3)).abs() < 1e-12);
        assert_eq!(t[2].line, 10);
    }

    #[test]
    fn a_short_pose_names_its_line() {
        let files = vec![ProgramFile {
            name: "p.script".into(),
            bytes: b"def p():\n  movel(p[0.5, 0, 0.3, 0, 3.14], a=1)\nend\n".to_vec(),
        }];
        match read(&files, &FilterOptions::default()) {
            Err(FilterError::Program(e)) => assert!(e.line == 2 && e.message.contains("5 numbers"), "{e}"),
            other => panic!("{other:?}"),
        }
        let files =
            vec![ProgramFile { name: "p.script".into(), bytes: b"def p():\n  textmsg(\"open)\nend\n".to_vec() }];
        assert!(matches!(read(&files, &FilterOptions::default()), Err(FilterError::Program(e)) if e.line == 2));
    }
}
