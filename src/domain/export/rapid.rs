//! `rapid`: a compensated target batch as an ABB RAPID module. Per compensated target a
//! `CONST robtarget p_<id>` (the fake pose with its confdata, for MoveL/MoveJ; written when the
//! answer has a confdata) and a `CONST jointtarget j_<id>` (the joints to command, for MoveAbsJ),
//! external axes 9E9. A target that was not compensated gets no declaration: it is listed in a
//! comment, and the caller reports the failure. The header comment names the robot, the parameter
//! set, the date and the frame the fake poses are in (and how to program them).
//!
//! Numbers are the compensation answer's, printed in their shortest form: positions to 0.1 µm,
//! quaternions to 1e-9 and joints to 1e-6 deg (the answer's output resolution), so the module's
//! values are the answer's values.
//!
//! The robtargets need a tool and a work object: the module declares both (`PERS tooldata
//! t_<set>`: the tool's declared TCP and payload, as the fake poses were computed with;
//! `PERS wobjdata w_<set>_<name>`: the work object the fake poses are in — {W} placed by the
//! set's nominal base, or the request's work object; none for wobj0). The text is ASCII
//! throughout (controllers read ISO-8859-1): comments are transliterated.

use super::ExportSource;
use crate::domain::CompensationResult;
use crate::domain::pose::FrameOut;
use crate::kinematics::Tool;
use crate::kinematics::frame::{Frame, quaternion_from_rot};
use crate::units::{MM, OUT_MM, OUT_UNIT, round_to};

/// RAPID's longest identifier.
pub const MAX_IDENTIFIER: usize = 32;

/// A target the module could not declare: its index in the batch, its id, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Unwritten {
    pub index: usize,
    pub id: Option<String>,
    pub error: String,
}

/// The module text and the targets it leaves out.
#[derive(Clone, Debug, PartialEq)]
pub struct RapidModule {
    pub text: String,
    pub failed: Vec<Unwritten>,
}

/// What the header says besides the set.
#[derive(Clone, Debug, PartialEq)]
pub struct RapidHeader<'a> {
    pub robot: &'a str,
    pub source: &'a ExportSource,
    /// When the module was written (RFC 3339).
    pub date: &'a str,
    pub frame: &'a FrameOut,
    /// Which tool the targets are for.
    pub tool: &'a str,
    /// That tool's declared TCP and payload (the fake poses' tool): declared as `tooldata`.
    pub tooldata: Option<&'a Tool>,
    /// The work object the fake poses are in (its name and frame in the base frame): declared as
    /// `wobjdata`; `None`: wobj0.
    pub work_object: Option<&'a (String, Frame)>,
}

/// The header's `tool` for targets compensated with the set's own (identified) tool, with the
/// note of a calibrated TCP far from the declared one where there is one
/// ([`crate::domain::validity::tool_note`]).
pub fn own_tool(note: Option<&str>) -> String {
    let own = "the parameter set's own (identified) tool";
    match note {
        Some(note) => format!("{own}; {note}"),
        None => own.to_string(),
    }
}

/// Whether `s` is a valid RAPID identifier: a letter, then letters, digits and underscores, at
/// most 32 characters.
pub fn is_identifier(s: &str) -> bool {
    let mut chars = s.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
        && s.len() <= MAX_IDENTIFIER
}

/// `prefix` + the target's id made an identifier (other characters → `_`), cut to 32 characters,
/// made unique (RAPID names are case-insensitive) with the target's number when needed.
fn identifier(prefix: &str, id: Option<&str>, index: usize, taken: &mut Vec<String>) -> String {
    let stem: String = match id {
        Some(id) if !id.trim().is_empty() => {
            id.trim().chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect()
        }
        _ => format!("t{}", index + 1),
    };
    let mut name: String = format!("{prefix}{stem}").chars().take(MAX_IDENTIFIER).collect();
    if taken.iter().any(|t| t.eq_ignore_ascii_case(&name)) {
        let suffix = format!("_{}", index + 1);
        name = name.chars().take(MAX_IDENTIFIER - suffix.len()).collect::<String>() + &suffix;
    }
    taken.push(name.clone());
    name
}

/// A number as RAPID reads it (no negative zero).
fn num(v: f64) -> String {
    if v == 0.0 { "0".to_string() } else { format!("{v}") }
}

fn list(v: &[f64]) -> String {
    v.iter().map(|x| num(*x)).collect::<Vec<_>>().join(",")
}

/// Text in ASCII (a controller reads ISO-8859-1): the symbols robocal's messages use spelled out,
/// anything else `?`.
pub fn ascii(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            c if c.is_ascii() => out.push(c),
            '\u{2013}' | '\u{2014}' | '\u{2212}' => out.push('-'),
            '\u{b0}' => out.push_str(" deg"),
            '\u{d7}' => out.push('x'),
            '\u{b7}' => out.push('*'),
            '\u{2026}' => out.push_str("..."),
            '\u{2018}' | '\u{2019}' => out.push('\''),
            '\u{201c}' | '\u{201d}' => out.push('"'),
            '\u{2264}' => out.push_str("<="),
            '\u{2265}' => out.push_str(">="),
            '\u{b1}' => out.push_str("+/-"),
            '\u{b5}' | '\u{3bc}' => out.push('u'),
            '\u{b2}' => out.push_str("^2"),
            '\u{b3}' => out.push_str("^3"),
            '\u{2192}' => out.push_str("->"),
            '\u{221a}' => out.push_str("sqrt"),
            '\u{3b1}' => out.push_str("alpha"),
            '\u{3b2}' => out.push_str("beta"),
            '\u{3b8}' => out.push_str("theta"),
            '\u{3c3}' => out.push_str("sigma"),
            '\u{3c4}' => out.push_str("tau"),
            '\u{3ba}' => out.push_str("kappa"),
            '\u{2032}' => out.push('\''),
            '\u{2033}' => out.push_str("''"),
            '\u{e9}' => out.push('e'),
            _ => out.push('?'),
        }
    }
    out
}

/// Text safe in a `!` comment line (one line, ASCII).
fn comment(s: &str) -> String {
    ascii(&s.replace(['\n', '\r'], " "))
}

/// `[[x,y,z],[q1,q2,q3,q4]]` of a frame (mm, quaternion), at the answer's output resolution.
fn pose(f: &Frame) -> String {
    let t: Vec<f64> = [f.t.x, f.t.y, f.t.z].iter().map(|v| round_to(v / MM, OUT_MM)).collect();
    let q: Vec<f64> = quaternion_from_rot(&f.r).iter().map(|v| round_to(*v, OUT_UNIT)).collect();
    format!("[[{}],[{}]]", list(&t), list(&q))
}

/// Wrap a long comment over lines of about 100 characters, each starting with `    ! `.
fn comment_lines(out: &mut String, text: &str) {
    let mut line = String::new();
    for word in comment(text).split_whitespace() {
        if !line.is_empty() && line.len() + word.len() > 96 {
            out.push_str(&format!("    ! {line}\n"));
            line.clear();
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        out.push_str(&format!("    ! {line}\n"));
    }
}

/// The module of a compensated batch (`results` in the batch's order).
pub fn write(header: &RapidHeader, results: &[CompensationResult]) -> RapidModule {
    let mut taken = Vec::new();
    let module = identifier("robocal_", Some(header.source.short.as_str()), 0, &mut taken);
    let mut out = format!("MODULE {module}\n");
    comment_lines(
        &mut out,
        &format!("robocal compensated (fake) targets: robot {}, {}", header.robot, header.source.label),
    );
    comment_lines(&mut out, &format!("written {}", header.date));
    comment_lines(&mut out, &format!("frame: {}: {}", header.frame.kind, header.frame.description));
    comment_lines(&mut out, &format!("tool: {}", header.tool));
    comment_lines(
        &mut out,
        "p_<target>: robtarget, the fake pose with its confdata (MoveJ/MoveL); j_<target>: jointtarget, the \
         compensated joints (MoveAbsJ). Positions mm, orientation quaternion [q1 = w, q2, q3, q4], joints deg.",
    );
    // The tool and the work object the robtargets are programmed with.
    let tool = identifier("t_", Some(header.source.short.as_str()), 0, &mut taken);
    let wobj = header
        .work_object
        .map(|(name, _)| identifier("w_", Some(&format!("{}_{name}", header.source.short)), 0, &mut taken));
    comment_lines(
        &mut out,
        &format!(
            "Program the robtargets with tool {} and work object {}, e.g.",
            if header.tooldata.is_some() { tool.as_str() } else { "(the tool named above)" },
            wobj.as_deref().unwrap_or("wobj0"),
        ),
    );
    out.push_str(&format!(
        "    !   MoveL p_<target>, v100, fine, {}{};\n",
        if header.tooldata.is_some() { tool.as_str() } else { "tool0" },
        wobj.as_deref().map(|w| format!("\\WObj:={w}")).unwrap_or_default()
    ));
    let mut prelude = String::new();
    if let Some(t) = header.tooldata {
        let tcp = Frame::from_xyzabc(&t.tcp);
        let com: Vec<f64> = [t.com.x, t.com.y, t.com.z].iter().map(|v| round_to(v / MM, OUT_MM)).collect();
        // A load of zero mass is refused by the controller: tool0's own load is 0.001 kg.
        let mass = if t.mass > 0.0 { t.mass } else { 0.001 };
        comment_lines(&mut prelude, "the tool: its declared TCP (the fake poses' tool) and payload");
        prelude.push_str(&format!(
            "    PERS tooldata {tool}:=[TRUE,{},[{},[{}],[1,0,0,0],0,0,0]];\n",
            pose(&tcp),
            num(mass),
            list(&com)
        ));
    }
    if let (Some((name, frame)), Some(w)) = (header.work_object, &wobj) {
        comment_lines(
            &mut prelude,
            &format!(
                "the work object the fake poses are in ({}), its user frame in the robot's base frame",
                if name == "W" { "{W}: the measurement frame placed by the set's nominal base" } else { name }
            ),
        );
        prelude.push_str(&format!("    PERS wobjdata {w}:=[FALSE,TRUE,\"\",{},[[0,0,0],[1,0,0,0]]];\n", pose(frame)));
    }
    let mut failed = Vec::new();
    let mut decls = String::new();
    for (i, r) in results.iter().enumerate() {
        let label = r.id.as_deref().map(|id| format!("targets[{i}] '{id}'")).unwrap_or_else(|| format!("targets[{i}]"));
        let (Some(joints), None) = (&r.joints_deg, &r.error) else {
            let error = r.error.clone().unwrap_or_else(|| "no joints in the answer".into());
            failed.push(Unwritten { index: i, id: r.id.clone(), error });
            continue;
        };
        let mut robax = [9e9; 6];
        let mut extax = [9e9; 6];
        for (k, v) in joints.iter().enumerate() {
            if k < 6 {
                robax[k] = *v;
            } else if k < 12 {
                extax[k - 6] = *v;
            }
        }
        let ext =
            extax.iter().map(|v| if *v == 9e9 { "9E9".to_string() } else { num(*v) }).collect::<Vec<_>>().join(",");
        let rob =
            robax.iter().map(|v| if *v == 9e9 { "9E9".to_string() } else { num(*v) }).collect::<Vec<_>>().join(",");
        let p = identifier("p_", r.id.as_deref(), i, &mut taken);
        let j = identifier("j_", r.id.as_deref(), i, &mut taken);
        decls.push_str(&format!("    ! {}\n", comment(&label)));
        match (&r.fake_pose, r.confdata) {
            (Some(pose), Some(cd)) => decls.push_str(&format!(
                "    CONST robtarget {p}:=[[{}],[{}],[{},{},{},{}],[{ext}]];\n",
                list(&pose.position_mm),
                list(&pose.quaternion),
                cd[0],
                cd[1],
                cd[2],
                cd[3]
            )),
            _ => decls.push_str("    ! no confdata in the answer (no closed-form IK): jointtarget only\n"),
        }
        decls.push_str(&format!("    CONST jointtarget {j}:=[[{rob}],[{ext}]];\n"));
    }
    if !failed.is_empty() {
        comment_lines(
            &mut out,
            &format!("NOT COMPENSATED ({} of {}), no declaration written:", failed.len(), results.len()),
        );
        for f in &failed {
            let label =
                f.id.as_deref()
                    .map(|id| format!("targets[{}] '{id}'", f.index))
                    .unwrap_or_else(|| format!("targets[{}]", f.index));
            comment_lines(&mut out, &format!("  {label}: {}", f.error));
        }
    }
    out.push_str(&prelude);
    out.push_str(&decls);
    out.push_str("ENDMODULE\n");
    RapidModule { text: out, failed }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::pose::{TargetFrames, compensate_targets};
    use crate::domain::{TargetSpec, from_json};
    use crate::kinematics::thesis::{irb120_table_5_1, trical_tool};
    use crate::kinematics::{Compensator, ParameterSet, Tool};

    /// The bracketed number lists of a declaration's value, in order: `[[1,2],[3]]` → [[1,2],[3]].
    fn groups(value: &str) -> Vec<Vec<f64>> {
        let inner = value.trim().strip_prefix('[').unwrap().strip_suffix(']').unwrap();
        inner
            .split("],")
            .map(|g| {
                g.trim_matches(|c| c == '[' || c == ']')
                    .split(',')
                    .map(|v| v.parse::<f64>().unwrap_or_else(|_| panic!("'{v}' is not a number")))
                    .collect()
            })
            .collect()
    }

    /// Every declaration as (type, name, groups); every other line a comment or the module frame.
    fn declarations(text: &str) -> Vec<(String, String, Vec<Vec<f64>>)> {
        let lines: Vec<&str> = text.lines().collect();
        assert!(lines[0].starts_with("MODULE ") && is_identifier(&lines[0][7..]), "{}", lines[0]);
        assert_eq!(*lines.last().unwrap(), "ENDMODULE");
        let mut out = Vec::new();
        for l in &lines[1..lines.len() - 1] {
            let l = l.trim();
            if l.starts_with('!') {
                continue;
            }
            let rest = l.strip_prefix("CONST ").unwrap_or_else(|| panic!("not a declaration: {l}"));
            let (ty, rest) = rest.split_once(' ').unwrap();
            let (name, value) = rest.split_once(":=").unwrap();
            assert!(is_identifier(name), "{name}");
            let value = value.strip_suffix(';').unwrap();
            out.push((ty.to_string(), name.to_string(), groups(value)));
        }
        out
    }

    fn header<'a>(source: &'a ExportSource, frame: &'a FrameOut) -> RapidHeader<'a> {
        RapidHeader {
            robot: "irb120",
            source,
            date: "2026-11-24T12:00:00Z",
            frame,
            tool: "the set's own",
            tooldata: None,
            work_object: None,
        }
    }

    /// The module declares the tooldata and wobjdata its robtargets are programmed with — the
    /// tool's declared TCP and load, the work object the fake poses are in ({W} placed by the
    /// set's nominal base) — and is ASCII throughout, whatever the messages held.
    #[test]
    fn it_declares_its_tool_and_work_object_in_ascii() {
        let set = irb120_table_5_1(trical_tool());
        let comp = Compensator::new(&set);
        let frames = TargetFrames::new(&comp, None, None).unwrap();
        let (name, wobj) = frames.work_object.clone().unwrap();
        assert_eq!(name, "W");
        let targets: Vec<TargetSpec> = from_json(
            r#"[{"id": "a", "joints_deg": [10, 20, -10, 0, 45, 0]},
                {"id": "far", "position_mm": [2000, 0, 300], "rotation_deg": [0, 90, 0], "cfx": 0}]"#,
        )
        .unwrap();
        let mut results = compensate_targets(&comp, 6, &frames, &crate::domain::validity::Guard::none(), &targets);
        results[1].error = Some("joint 3 at 170.000° is 5.000° beyond [−110, 70]° – σ µm".into());
        let source = ExportSource::stored("set-1", 4);
        let module = write(
            &RapidHeader {
                tooldata: Some(&set.tool),
                work_object: frames.work_object.as_ref(),
                ..header(&source, &frames.out)
            },
            &results,
        );
        let text = &module.text;
        assert!(text.is_ascii(), "{text}");
        assert!(text.contains("170.000 deg") && text.contains("-110") && text.contains("sigma um"), "{text}");
        let pers: Vec<&str> = text.lines().map(str::trim).filter(|l| l.starts_with("PERS ")).collect();
        assert_eq!(pers.len(), 2, "{text}");
        // PERS tooldata t_v4:=[TRUE,[[40,0,130],[1,0,0,0]],[1.7,[30,0,64],[1,0,0,0],0,0,0]];
        let tool = pers[0].strip_prefix("PERS tooldata t_v4:=[TRUE,").unwrap().strip_suffix("];").unwrap();
        assert_eq!(tool, "[[40,0,130],[1,0,0,0]],[1.7,[30,0,64],[1,0,0,0],0,0,0]");
        // PERS wobjdata w_v4_W:=[FALSE,TRUE,"",[[x,y,z],[q]],[[0,0,0],[1,0,0,0]]]; uframe = (T_0^W)⁻¹.
        let w = pers[1].strip_prefix("PERS wobjdata w_v4_W:=[FALSE,TRUE,\"\",").unwrap();
        let uframe = groups(&w[..w.find("]],").unwrap() + 2]);
        let inv = set.nominal_chain().base().inverse();
        assert_eq!(wobj, inv);
        for k in 0..3 {
            assert!((uframe[0][k] - inv.t[k] / crate::units::MM).abs() <= 0.5e-4, "{uframe:?}");
        }
        let q = quaternion_from_rot(&inv.r);
        for k in 0..4 {
            assert!((uframe[1][k] - q[k]).abs() <= 0.5e-9, "{uframe:?}");
        }
        // How to program them, in the header.
        assert!(text.contains("    !   MoveL p_<target>, v100, fine, t_v4\\WObj:=w_v4_W;\n"), "{text}");
        // In the base frame: wobj0, nothing declared for it.
        let frames = TargetFrames::new(&comp, Some(crate::domain::pose::FrameKind::Base), None).unwrap();
        assert!(frames.work_object.is_none());
    }

    /// A batch compensated by `compensate_targets`, written as RAPID and parsed back: each
    /// compensated target's joints and fake pose are the answer's, a failed target is listed and
    /// not declared, and the names are valid and unique.
    #[test]
    fn declarations_read_back_to_the_answer() {
        let set = irb120_table_5_1(trical_tool());
        let comp = Compensator::new(&set);
        let targets: Vec<TargetSpec> = from_json(
            r#"[{"id": "pick-1", "position_mm": [400, -50, 300], "rotation_deg": [0, 90, 0], "cfx": 0},
                {"id": "Pick 1", "position_mm": [380, 60, 350], "quaternion": [0.5, 0.5, 0.5, 0.5], "cfx": 0},
                {"joints_deg": [10, 20, -10, 0, 45, 0]},
                {"id": "too-far", "position_mm": [2000, 0, 300], "rotation_deg": [0, 90, 0], "cfx": 0},
                {"id": "a-very-long-target-name-beyond-thirty-two", "joints_deg": [0, 0, 0, 0, 30, 0]}]"#,
        )
        .unwrap();
        let frames = TargetFrames::world();
        let results = compensate_targets(&comp, 6, &frames, &crate::domain::validity::Guard::none(), &targets);
        assert!(results[3].error.is_some() && results.iter().filter(|r| r.error.is_some()).count() == 1);
        let source = ExportSource::stored("abc", 4);
        let m = write(&header(&source, &frames.out), &results);
        assert_eq!(m.failed.len(), 1);
        assert_eq!((m.failed[0].index, m.failed[0].id.as_deref()), (3, Some("too-far")));
        assert!(m.text.contains("targets[3] 'too-far'") && m.text.contains("NOT COMPENSATED (1 of 5)"), "{}", m.text);
        assert!(m.text.contains("irb120") && m.text.contains("version 4") && m.text.contains("2026-11-24T12:00:00Z"));
        assert!(m.text.contains("frame: world"));
        let decls = declarations(&m.text);
        assert_eq!(decls.len(), 8, "{}", m.text);
        let names: Vec<String> = decls.iter().map(|d| d.1.to_ascii_lowercase()).collect();
        let mut unique = names.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), names.len(), "{names:?}");
        assert!(names.contains(&"p_pick_1".to_string()) && names.contains(&"p_pick_1_2".to_string()), "{names:?}");
        assert!(names.contains(&"j_t3".to_string()));
        assert!(names.iter().all(|n| n.len() <= 32));
        for (i, r) in results.iter().enumerate().filter(|(i, _)| *i != 3) {
            let joints = decls.iter().filter(|d| d.0 == "jointtarget").nth(if i > 3 { i - 1 } else { i }).unwrap();
            assert_eq!(joints.2[0], *r.joints_deg.as_ref().unwrap(), "target {i}");
            assert_eq!(joints.2[1], [9e9; 6]);
            let pose = decls.iter().filter(|d| d.0 == "robtarget").nth(if i > 3 { i - 1 } else { i }).unwrap();
            let fake = r.fake_pose.as_ref().unwrap();
            assert_eq!(pose.2[0], fake.position_mm);
            assert_eq!(pose.2[1], fake.quaternion);
            let cd = r.confdata.unwrap();
            assert_eq!(pose.2[2], cd.map(f64::from));
            assert_eq!(pose.2[3], [9e9; 6]);
        }
    }

    /// Without a closed-form IK there is no confdata: jointtargets only, said in a comment.
    #[test]
    fn a_robot_without_confdata_gets_jointtargets() {
        let set = ParameterSet::nominal(crate::kinematics::model::ur10(), Tool::flange(), [0.0; 6]);
        let comp = Compensator::new(&set);
        let targets: Vec<TargetSpec> = from_json(r#"[{"id": "home", "joints_deg": [0, -90, 90, 0, 90, 0]}]"#).unwrap();
        let frames = TargetFrames::world();
        let results = compensate_targets(&comp, 6, &frames, &crate::domain::validity::Guard::none(), &targets);
        let source = ExportSource::file("ur10.json");
        let m = write(&header(&source, &frames.out), &results);
        let decls = declarations(&m.text);
        if results[0].confdata.is_none() {
            assert_eq!(decls.len(), 1, "{}", m.text);
            assert!(m.text.contains("jointtarget only"));
        }
        assert_eq!(decls.iter().find(|d| d.0 == "jointtarget").unwrap().2[0], *results[0].joints_deg.as_ref().unwrap());
        assert!(m.text.starts_with("MODULE robocal_ur10\n"));
    }

    #[test]
    fn identifiers_are_checked() {
        assert!(is_identifier("p_t1") && is_identifier("A"));
        assert!(
            !is_identifier("1a") && !is_identifier("_a") && !is_identifier("a-b") && !is_identifier(&"a".repeat(33))
        );
        let mut taken = Vec::new();
        assert_eq!(identifier("p_", Some("x y"), 0, &mut taken), "p_x_y");
        assert_eq!(identifier("p_", Some("X-Y"), 1, &mut taken), "p_X_Y_2");
        assert_eq!(identifier("p_", None, 4, &mut taken), "p_t5");
        let long = identifier("j_", Some(&"z".repeat(40)), 9, &mut taken);
        assert_eq!(long.len(), 32);
        let again = identifier("j_", Some(&"z".repeat(40)), 10, &mut taken);
        assert!(again.ends_with("_11") && again.len() == 32 && is_identifier(&again));
    }
}
