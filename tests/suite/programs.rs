//! Seeded generators of realistic robot programs for the filter tests and benchmark: RAPID, KRL
//! (.src + .dat), Fanuc TP text and URScript, with several tools and work frames, named and inline
//! targets, joint targets, comments and strings holding target-like text that must not be touched,
//! the controllers' own line endings and an ISO-8859-1 byte where the controller reads that.
//!
//! Every pose is where the *nominal* model puts the TCP at random joints within the limits (away
//! from singularities), written with the configuration the controller gives those joints: what an
//! offline-programming tool writes. A few targets are out of reach on purpose (`Sample::failing`).
#![allow(dead_code)]

use std::collections::HashMap;
use std::fmt::Write as _;

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robocal::domain::program::{AngleOrder, GivenFrames, ProgramFile};
use robocal::kinematics::frame::{quaternion_from_rot, rotation_vector, zyx_from_rot};
use robocal::kinematics::thesis::{irb120_table_5_1, trical_tool};
use robocal::kinematics::{AnalyticIk, Frame, JointState, JointTerm, Param, ParameterSet, Tool};

pub const DEG: f64 = std::f64::consts::PI / 180.0;

/// A generated program: its files, the frames to give, what must fail, and for URScript the
/// joints each pose was made from (by line and name).
pub struct Sample {
    pub files: Vec<ProgramFile>,
    pub frames: GivenFrames,
    pub failing: Vec<String>,
    pub joints: HashMap<(usize, String), Vec<f64>>,
    pub seed_joints: Option<Vec<f64>>,
}

/// The IRB 120 as the thesis identified it (Table 5.1).
pub fn irb120_set() -> ParameterSet {
    irb120_table_5_1(trical_tool())
}

/// A "calibrated" UR10: the nominal preset with errors of the size an identification finds.
pub fn ur10_set() -> ParameterSet {
    let tool = Tool { tcp: [0.0, 0.0, 0.1, 0.0, 0.0, 0.0], mass: 1.0, com: Vector3::new(0.0, 0.0, 0.05) };
    let mut set = ParameterSet::nominal(robocal::kinematics::model::ur10(), tool, [0.0; 6]);
    set.set(Param::A(2), -0.6125);
    set.set(Param::A(3), -0.5719);
    set.set(Param::D(4), 0.16420);
    set.set(Param::Theta(1), 0.002);
    set.set(Param::Theta(3), -0.0015);
    set.set(Param::Beta(2), 0.001);
    set.set(Param::Joint(1, JointTerm::Compliance), -2e-5);
    set
}

/// The nominal pose of `tool`'s TCP at `q` in work frame `base` (given in the base frame).
pub fn nominal_pose(set: &ParameterSet, tool: &Tool, base: &Frame, q: &[f64]) -> Frame {
    let s = set.with_tool(tool.clone());
    let chain = s.nominal_chain();
    base.inverse().compose(&chain.base().inverse()).compose(&chain.fk(&JointState::new(q)))
}

/// The controller's configuration of `q` with `tool` (the nominal closed form).
pub fn confdata(set: &ParameterSet, tool: &Tool, q: &[f64]) -> robocal::kinematics::Confdata {
    let s = set.with_tool(tool.clone());
    let chain = s.nominal_chain();
    AnalyticIk::new(&s.model, chain.base(), chain.tool()).unwrap().confdata(q)
}

/// Random IRB 120 joints inside the limits and away from the wrist, elbow and shoulder
/// singularities.
pub fn irb120_joints(rng: &mut ChaCha8Rng, set: &ParameterSet) -> [f64; 6] {
    let flange = set.with_tool(Tool::flange());
    let chain = flange.nominal_chain();
    loop {
        let q = [
            rng.random_range(-150.0..150.0) * DEG,
            rng.random_range(-60.0..80.0) * DEG,
            rng.random_range(-95.0..50.0) * DEG,
            rng.random_range(-150.0..150.0) * DEG,
            rng.random_range(-110.0..110.0) * DEG,
            rng.random_range(-300.0..300.0) * DEG,
        ];
        if q[4].abs() < 15.0 * DEG || (q[2] + 76.96 * DEG).abs() < 15.0 * DEG {
            continue;
        }
        let f = chain.base().inverse().compose(&chain.fk(&JointState::new(&q)));
        let wc = f.t - f.r.column(2) * 0.072;
        if wc.x.hypot(wc.y) < 0.12 {
            continue;
        }
        return q;
    }
}

fn quat(f: &Frame) -> [f64; 4] {
    quaternion_from_rot(&f.r)
}

fn abc_deg(f: &Frame) -> [f64; 3] {
    zyx_from_rot(&f.r).map(|v| v / DEG)
}

fn frame(p_mm: [f64; 3], abc: [f64; 3]) -> Frame {
    Frame::from_xyzabc(&[p_mm[0] * 1e-3, p_mm[1] * 1e-3, p_mm[2] * 1e-3, abc[0] * DEG, abc[1] * DEG, abc[2] * DEG])
}

fn tool(p_mm: [f64; 3], abc: [f64; 3], mass: f64, com_mm: [f64; 3]) -> Tool {
    Tool { tcp: frame(p_mm, abc).to_xyzabc(), mass, com: Vector3::new(com_mm[0], com_mm[1], com_mm[2]) * 1e-3 }
}

/// Tools and work frames of the IRB 120 cell: (name, tool) and (name, frame in the base frame).
fn irb120_tools() -> Vec<(&'static str, Tool)> {
    vec![
        ("tool0", Tool::flange()),
        ("gun", tool([30.0, 0.0, 210.0], [0.0, 45.0, 0.0], 2.5, [0.0, 0.0, 80.0])),
        ("gripper", tool([0.0, 0.0, 150.0], [0.0, 0.0, 0.0], 1.2, [0.0, 0.0, 60.0])),
        ("probe", tool([-20.0, 40.0, 120.0], [90.0, 0.0, 10.0], 0.6, [0.0, 10.0, 50.0])),
    ]
}

fn irb120_bases() -> Vec<(&'static str, Frame)> {
    vec![
        ("wobj0", Frame::identity()),
        ("table", frame([400.0, -100.0, 50.0], [30.0, 0.0, 0.0]).compose(&frame([0.0, 0.0, 10.0], [0.0, 0.0, 0.0]))),
        ("fixture", frame([300.0, 200.0, -20.0], [-45.0, 5.0, 0.0])),
    ]
}

fn join(v: &[f64], decimals: usize) -> String {
    v.iter().map(|x| format!("{x:.decimals$}")).collect::<Vec<_>>().join(",")
}

/// A RAPID module: CONST/PERS/VAR robtargets, an array, inline targets in MoveL/MoveJ/MoveC, a
/// target used through Offs, jointtargets with MoveAbsJ; tooldata and wobjdata declared; CRLF line
/// endings and an ISO-8859-1 comment. About `n` pose targets.
pub fn rapid(seed: u64, n: usize) -> Sample {
    let set = irb120_set();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let tools = irb120_tools();
    let bases = irb120_bases();
    let mut decl = String::new();
    let mut body = String::new();
    let robtarget = |q: &[f64; 6], t: usize, b: usize| -> String {
        let f = nominal_pose(&set, &tools[t].1, &bases[b].1, q);
        let c = confdata(&set, &tools[t].1, q);
        format!(
            "[[{:.3},{:.3},{:.3}],[{}],[{},{},{},{}],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]]",
            f.t.x * 1e3,
            f.t.y * 1e3,
            f.t.z * 1e3,
            join(&quat(&f), 6),
            c.cf1,
            c.cf4,
            c.cf6,
            c.cfx.cfx()
        )
    };
    let motion = |t: usize, b: usize| -> String {
        if bases[b].0 == "wobj0" { tools[t].0.to_string() } else { format!("{}\\WObj:={}", tools[t].0, bases[b].0) }
    };
    let mut k = 0;
    let mut joint_count = 0;
    while k < n {
        let t = rng.random_range(0..tools.len());
        let b = rng.random_range(0..bases.len());
        let q = irb120_joints(&mut rng, &set);
        match rng.random_range(0..10) {
            0..=4 => {
                let kw = ["CONST", "PERS", "VAR", "LOCAL CONST", "TASK PERS"][rng.random_range(0..5)];
                let name = format!("p{}", k + 10);
                let value = robtarget(&q, t, b);
                if k % 7 == 3 {
                    // Declarations may span lines.
                    let (head, tail) = value.split_at(value.find("],[").unwrap() + 2);
                    writeln!(decl, "  {kw} robtarget {name}:={head}\r\n      {tail};").unwrap();
                } else {
                    writeln!(decl, "  {kw} robtarget {name}:={value};\r").unwrap();
                }
                let instr = ["MoveL", "MoveJ"][rng.random_range(0..2)];
                if k % 11 == 5 {
                    writeln!(body, "    MoveL Offs({name},0,0,20), v200, z10, {};\r", motion(t, b)).unwrap();
                }
                writeln!(body, "    {instr} {name}, v1000, z50, {};\r", motion(t, b)).unwrap();
                k += 1;
            }
            5..=6 => {
                writeln!(body, "    MoveL {}, v200, fine, {};\r", robtarget(&q, t, b), motion(t, b)).unwrap();
                k += 1;
            }
            7 => {
                let q2 = irb120_joints(&mut rng, &set);
                writeln!(
                    body,
                    "    MoveC {}, {}, v100, z5, {};\r",
                    robtarget(&q, t, b),
                    robtarget(&q2, t, b),
                    motion(t, b)
                )
                .unwrap();
                k += 2;
            }
            8 => {
                let name = format!("seam{}", k);
                let q2 = irb120_joints(&mut rng, &set);
                let q3 = irb120_joints(&mut rng, &set);
                writeln!(
                    decl,
                    "  CONST robtarget {name}{{3}}:=[{},\r\n      {},\r\n      {}];\r",
                    robtarget(&q, t, b),
                    robtarget(&q2, t, b),
                    robtarget(&q3, t, b)
                )
                .unwrap();
                writeln!(body, "    MoveL {name}{{1}}, v100, z1, {};\r", motion(t, b)).unwrap();
                writeln!(body, "    MoveL {name}{{3}}, v100, z1, {};\r", motion(t, b)).unwrap();
                k += 3;
            }
            _ => {
                joint_count += 1;
                let name = format!("j{joint_count}");
                let qd: Vec<f64> = q.iter().map(|v| v / DEG).collect();
                writeln!(
                    decl,
                    "  CONST jointtarget {name}:=[[{}],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];\r",
                    join(&qd, 4)
                )
                .unwrap();
                writeln!(body, "    MoveAbsJ {name}\\NoEOffs, v1000, z50, {};\r", tools[t].0).unwrap();
            }
        }
    }
    // Out of reach, on purpose.
    decl.push_str(
        "  CONST robtarget p_far:=[[2000,0,300],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];\r\n",
    );
    body.push_str("    MoveL p_far, v100, fine, gun;\r\n");
    let mut text = String::from("%%%\r\n  VERSION:1\r\n  LANGUAGE:ENGLISH\r\n%%%\r\n\r\nMODULE WeldCell\r\n");
    text.push_str("  ! Generated for the filter tests. MoveL [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, z10, tool0;\r\n");
    text.push_str("  ! Schwei\u{fffd}naht 3 \u{2014} seam 3\r\n");
    text.push_str(
        "  PERS tooldata gun:=[TRUE,[[30,0,210],[0.92388,0,0.382683,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];\r\n",
    );
    text.push_str("  PERS tooldata gripper:=[TRUE,[[0,0,150],[1,0,0,0]],[1.2,[0,0,60],[1,0,0,0],0,0,0]];\r\n");
    let probe = &tools[3].1;
    let pq = quaternion_from_rot(&Frame::from_xyzabc(&probe.tcp).r);
    writeln!(
        text,
        "  PERS tooldata probe:=[TRUE,[[-20,40,120],[{}]],[0.6,[0,10,50],[1,0,0,0],0,0,0]];\r",
        join(&pq, 9)
    )
    .unwrap();
    text.push_str("  TASK PERS wobjdata table:=[FALSE,TRUE,\"\",[[400,-100,50],[0.965925826,0,0,0.258819045]],[[0,0,10],[1,0,0,0]]];\r\n");
    let fx = bases[2].1;
    writeln!(
        text,
        "  PERS wobjdata fixture:=[FALSE,TRUE,\"\",[[300,200,-20],[{}]],[[0,0,0],[1,0,0,0]]];\r",
        join(&quat(&fx), 9)
    )
    .unwrap();
    text.push_str(&decl);
    text.push_str("\r\n  PROC main()\r\n");
    text.push_str("    TPWrite \"Reached p10:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]\";\r\n");
    text.push_str(&body);
    text.push_str("  ENDPROC\r\nENDMODULE\r\n");
    // The ISO-8859-1 ß of "Schweißnaht" (a RAPID module is read as ISO-8859-1).
    let bytes: Vec<u8> =
        text.replace("\u{fffd}", "\u{df}").replace("\u{2014}", "-").chars().map(|c| c as u32 as u8).collect();
    Sample {
        files: vec![ProgramFile { name: "weldcell.mod".into(), bytes }],
        frames: GivenFrames::default(),
        failing: vec!["p_far".into()],
        joints: HashMap::new(),
        seed_joints: None,
    }
}

/// KUKA status and turn of joints `q` (see `domain::program::krl`).
fn kuka_st(set: &ParameterSet, t: &Tool, q: &[f64; 6]) -> (u32, u32) {
    let b = confdata(set, t, q).cfx;
    let s = u32::from(b.shoulder_back()) | u32::from(b.elbow_behind()) << 1 | u32::from(b.wrist_negative()) << 2;
    let tt = q.iter().enumerate().filter(|(_, v)| **v < 0.0).fold(0, |acc, (j, _)| acc | 1 << j);
    (s, tt)
}

/// A KRL pair: inline-form motions (FOLDs with FDAT/PDAT), E6POS and E6AXIS points in the .dat,
/// `$TOOL`/`$BASE` set by hand, inline aggregates in the .src, a CIRC; tools and bases by number
/// (given), a FRAME tool declared in the .dat.
pub fn krl(seed: u64, n: usize) -> Sample {
    let set = irb120_set();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let tools: Vec<(&str, Tool)> = vec![
        ("1", irb120_tools()[1].1.clone()),
        ("2", irb120_tools()[2].1.clone()),
        ("gripframe", tool([0.0, 0.0, 180.0], [0.0, 0.0, 0.0], 0.0, [0.0; 3])),
    ];
    let bases: Vec<(&str, Frame)> =
        vec![("0", Frame::identity()), ("1", irb120_bases()[1].1), ("2", irb120_bases()[2].1)];
    let mut frames = GivenFrames::default();
    let fmt_frame = |f: &Frame| {
        let [a, b, c] = abc_deg(f);
        format!("{:.6},{:.6},{:.6},{a:.9},{b:.9},{c:.9}", f.t.x * 1e3, f.t.y * 1e3, f.t.z * 1e3)
    };
    for (name, t) in &tools[..2] {
        let spec = format!(
            "{name}:{},{},{:.6},{:.6},{:.6}",
            fmt_frame(&Frame::from_xyzabc(&t.tcp)),
            t.mass,
            t.com.x * 1e3,
            t.com.y * 1e3,
            t.com.z * 1e3
        );
        frames.add_tool(&spec, AngleOrder::Abc, "--tool").unwrap();
    }
    for (name, b) in &bases[1..] {
        frames.add_base(&format!("{name}:{}", fmt_frame(b)), AngleOrder::Abc, "--base").unwrap();
    }
    // The given frames are the ones the targets are made with (rounded as given).
    let tool_of = |i: usize| if i < 2 { frames.tools[tools[i].0].clone() } else { tools[2].1.clone() };
    let base_of = |i: usize| if i == 0 { Frame::identity() } else { frames.bases[bases[i].0] };
    let e6pos = |q: &[f64; 6], t: usize, b: usize| -> String {
        let tl = tool_of(t);
        let f = nominal_pose(&set, &tl, &base_of(b), q);
        let [a, bb, c] = abc_deg(&f);
        let (s, tt) = kuka_st(&set, &tl, q);
        format!(
            "{{X {:.4},Y {:.4},Z {:.4},A {a:.5},B {bb:.5},C {c:.5},S {s},T {tt},E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}",
            f.t.x * 1e3,
            f.t.y * 1e3,
            f.t.z * 1e3
        )
    };
    let mut dat = String::from(
        "&ACCESS RVP\r\n&REL 12\r\n&PARAM TEMPLATE = C:\\KRC\\Roboter\\Template\\vorgabe\r\nDEFDAT  WELDCELL\r\n",
    );
    dat.push_str(";FOLD EXTERNAL DECLARATIONS;%{PE}%V3.2.0,%MKUKATPBASIS,%CEXT,%VCOMMON,%P\r\n;ENDFOLD (EXTERNAL DECLARATIONS)\r\n");
    dat.push_str("; Schwei\u{fffd}punkte: DECL E6POS XP0={X 1,Y 2,Z 3,A 0,B 0,C 0,S 2,T 0}\r\n");
    dat.push_str("DECL FRAME GRIPFRAME={X 0.0,Y 0.0,Z 180.0,A 0.0,B 0.0,C 0.0}\r\n");
    let mut src = String::from(
        "&ACCESS RVP\r\n&REL 12\r\n&PARAM TEMPLATE = C:\\KRC\\Roboter\\Template\\vorgabe\r\n&PARAM EDITMASK = *\r\nDEF WELDCELL( )\r\n",
    );
    src.push_str(";FOLD INI;%{PE}\r\n  ;FOLD BASISTECH INI\r\n    GLOBAL INTERRUPT DECL 3 WHEN $STOPMESS==TRUE DO IR_STOPM ( )\r\n    INTERRUPT ON 3 \r\n    BAS (#INITMOV,0 )\r\n  ;ENDFOLD (BASISTECH INI)\r\n;ENDFOLD (INI)\r\n\r\n");
    let mut k = 0;
    let mut joint_count = 0;
    let mut manual: Option<(usize, usize)> = None;
    while k < n {
        let q = irb120_joints(&mut rng, &set);
        match rng.random_range(0..10) {
            0..=5 => {
                // An inline form: FOLD, FDAT with the tool and base numbers, the point in the .dat.
                let t = rng.random_range(0..2);
                let b = rng.random_range(0..3);
                let p = k + 1;
                let (mv, v) = if rng.random_bool(0.5) { ("LIN", "2 m/s") } else { ("PTP", "100 %") };
                writeln!(
                    src,
                    ";FOLD {mv} P{p} Vel={v} CPDAT{p} Tool[{}]:tool{} Base[{}]:base{};%{{PE}}%R 8.3.31,%MKUKATPBASIS,%CMOVE,%V{mv},%P 1:{mv}, 2:P{p}, 3:, 5:2, 7:CPDAT{p}\r\n$BWDSTART=FALSE\r\nLDAT_ACT=LCPDAT{p}\r\nFDAT_ACT=FP{p}\r\nBAS(#CP_PARAMS,2)\r\n{mv} XP{p} \r\n;ENDFOLD\r",
                    tools[t].0, tools[t].0, bases[b].0, bases[b].0
                )
                .unwrap();
                writeln!(dat, "DECL E6POS XP{p}={}\r", e6pos(&q, t, b)).unwrap();
                writeln!(
                    dat,
                    "DECL FDAT FP{p}={{TOOL_NO {},BASE_NO {},IPO_FRAME #BASE,POINT2[] \" \",TQ_STATE FALSE}}\r",
                    tools[t].0, bases[b].0
                )
                .unwrap();
                writeln!(dat, "DECL LDAT LCPDAT{p}={{VEL 2.0,ACC 100.0,APO_DIST 100.0,APO_FAC 50.0,ORI_TYP #VAR,CIRC_TYP #BASE,JERK_FAC 50.0}}\r").unwrap();
                manual = None;
                k += 1;
            }
            6..=7 => {
                // By hand: $TOOL and $BASE set, an inline aggregate.
                let t = [0, 2][rng.random_range(0..2)];
                let b = rng.random_range(1..3);
                if manual != Some((t, b)) {
                    let tl = if t == 2 { "GRIPFRAME".to_string() } else { format!("TOOL_DATA[{}]", tools[t].0) };
                    writeln!(src, "$TOOL = {tl}\r\n$BASE=BASE_DATA[{}]\r", bases[b].0).unwrap();
                    manual = Some((t, b));
                }
                writeln!(
                    src,
                    "LIN {} C_DIS ; hand-written\r",
                    e6pos(&q, t, b).replace(",E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0", "")
                )
                .unwrap();
                k += 1;
            }
            8 => {
                let t = 1;
                let b = 1;
                if manual != Some((t, b)) {
                    writeln!(src, "BAS(#TOOL,{})\r\nBAS(#BASE,{})\r", tools[t].0, bases[b].0).unwrap();
                    manual = Some((t, b));
                }
                let q2 = irb120_joints(&mut rng, &set);
                writeln!(dat, "DECL E6POS XA{k}={}\r\nDECL E6POS XE{k}={}\r", e6pos(&q, t, b), e6pos(&q2, t, b))
                    .unwrap();
                writeln!(src, "CIRC XA{k}, XE{k} C_VEL\r").unwrap();
                k += 2;
            }
            _ => {
                let qd: Vec<f64> = q.iter().map(|v| v / DEG).collect();
                joint_count += 1;
                let k = joint_count;
                writeln!(
                    dat,
                    "DECL E6AXIS XJ{k}={{A1 {:.4},A2 {:.4},A3 {:.4},A4 {:.4},A5 {:.4},A6 {:.4},E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}\r",
                    qd[0], qd[1], qd[2], qd[3], qd[4], qd[5]
                )
                .unwrap();
                if manual.is_none() {
                    writeln!(src, "$TOOL = TOOL_DATA[1]\r\n$BASE = $NULLFRAME\r").unwrap();
                    manual = Some((0, 0));
                }
                writeln!(src, "PTP XJ{k} ; PTP {{A1 0,A2 -90}} in a comment\r").unwrap();
            }
        }
    }
    // Out of reach, on purpose: with tool 1, base 0.
    dat.push_str("DECL E6POS XFAR={X 2500.0,Y 0.0,Z 300.0,A 0.0,B 90.0,C 0.0,S 2,T 0,E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}\r\n");
    src.push_str("$TOOL = TOOL_DATA[1]\r\n$BASE = $NULLFRAME\r\nLIN XFAR\r\n");
    dat.push_str("ENDDAT\r\n");
    src.push_str("END\r\n");
    let latin1 = |s: String| -> Vec<u8> { s.replace("\u{fffd}", "\u{df}").chars().map(|c| c as u32 as u8).collect() };
    Sample {
        files: vec![
            ProgramFile { name: "weldcell.src".into(), bytes: latin1(src) },
            ProgramFile { name: "weldcell.dat".into(), bytes: latin1(dat) },
        ],
        frames,
        failing: vec!["XFAR".into()],
        joints: HashMap::new(),
        seed_joints: None,
    }
}

/// A Fanuc TP program as text: /MN motions and comments with position-like text, /POS with
/// Cartesian positions (several UF/UT, CONFIG with turn numbers) and joint positions, a second
/// motion group on some.
pub fn fanuc(seed: u64, n: usize) -> Sample {
    let set = irb120_set();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let tools: Vec<(&str, Tool)> =
        vec![("0", Tool::flange()), ("1", irb120_tools()[1].1.clone()), ("2", irb120_tools()[3].1.clone())];
    let bases: Vec<(&str, Frame)> =
        vec![("0", Frame::identity()), ("1", irb120_bases()[1].1), ("3", irb120_bases()[2].1)];
    let mut frames = GivenFrames::default();
    let wpr = |f: &Frame| {
        let [a, b, c] = abc_deg(f);
        format!("{:.6},{:.6},{:.6},{c:.9},{b:.9},{a:.9}", f.t.x * 1e3, f.t.y * 1e3, f.t.z * 1e3)
    };
    for (name, t) in &tools[1..] {
        let spec = format!(
            "{name}:{},{},{:.6},{:.6},{:.6}",
            wpr(&Frame::from_xyzabc(&t.tcp)),
            t.mass,
            t.com.x * 1e3,
            t.com.y * 1e3,
            t.com.z * 1e3
        );
        frames.add_tool(&spec, AngleOrder::Wpr, "--utool").unwrap();
    }
    for (name, b) in &bases[1..] {
        frames.add_base(&format!("{name}:{}", wpr(b)), AngleOrder::Wpr, "--uframe").unwrap();
    }
    let tool_of = |i: usize| if i == 0 { Tool::flange() } else { frames.tools[tools[i].0].clone() };
    let base_of = |i: usize| if i == 0 { Frame::identity() } else { frames.bases[bases[i].0] };
    let mut mn = String::new();
    let mut pos = String::new();
    let mut line = 0;
    let mut uf = usize::MAX;
    let mut ut = usize::MAX;
    for p in 1..=n + 1 {
        let q = irb120_joints(&mut rng, &set);
        let t = rng.random_range(0..tools.len());
        let b = rng.random_range(0..bases.len());
        if uf != b {
            line += 1;
            writeln!(mn, "{line:>4}:  UFRAME_NUM={} ;", bases[b].0).unwrap();
            uf = b;
        }
        if ut != t {
            line += 1;
            writeln!(mn, "{line:>4}:  UTOOL_NUM={} ;", tools[t].0).unwrap();
            ut = t;
        }
        if p % 17 == 0 {
            line += 1;
            writeln!(mn, "{line:>4}:  !P[{p}] X = 100.000 mm, CONFIG : 'N U T, 0, 0, 0' ;").unwrap();
        }
        line += 1;
        let motion =
            if rng.random_bool(0.5) { format!("J P[{p}] 100% FINE") } else { format!("L P[{p}] 500mm/sec CNT100") };
        writeln!(mn, "{line:>4}:{motion}    ;").unwrap();
        let comment = if p % 5 == 0 { format!(":\"point {p}\"") } else { String::new() };
        writeln!(pos, "P[{p}{comment}]{{\n   GP1:").unwrap();
        if p == n + 1 {
            // Out of reach, on purpose.
            pos.push_str("\tUF : 0, UT : 1,\t\tCONFIG : 'N U T, 0, 0, 0',\n\tX =  2500.000  mm,\tY =     0.000  mm,\tZ =   300.000  mm,\n\tW =   180.000 deg,\tP =     0.000 deg,\tR =     0.000 deg\n};\n");
            continue;
        }
        if p % 9 == 4 {
            let qd: Vec<f64> = q.iter().map(|v| v / DEG).collect();
            writeln!(
                pos,
                "\tUF : {}, UT : {},\t\n\tJ1= {:>9.3} deg,\tJ2= {:>9.3} deg,\tJ3= {:>9.3} deg,\n\tJ4= {:>9.3} deg,\tJ5= {:>9.3} deg,\tJ6= {:>9.3} deg",
                bases[b].0, tools[t].0, qd[0], qd[1], qd[2], qd[3], qd[4], qd[5]
            )
            .unwrap();
        } else {
            let tl = tool_of(t);
            let f = nominal_pose(&set, &tl, &base_of(b), &q);
            let [a, bb, c] = abc_deg(&f);
            let cd = confdata(&set, &tl, &q).cfx;
            let turn = |v: f64| ((v + std::f64::consts::PI) / std::f64::consts::TAU).floor() as i64;
            writeln!(
                pos,
                "\tUF : {}, UT : {},\t\tCONFIG : '{} {} {}, {}, {}, {}',\n\tX = {:>9.3}  mm,\tY = {:>9.3}  mm,\tZ = {:>9.3}  mm,\n\tW = {c:>9.3} deg,\tP = {bb:>9.3} deg,\tR = {a:>9.3} deg",
                bases[b].0,
                tools[t].0,
                if cd.wrist_negative() { 'F' } else { 'N' },
                if cd.elbow_behind() { 'D' } else { 'U' },
                if cd.shoulder_back() { 'B' } else { 'T' },
                turn(q[3]),
                turn(q[4]),
                turn(q[5]),
                f.t.x * 1e3,
                f.t.y * 1e3,
                f.t.z * 1e3
            )
            .unwrap();
        }
        if p % 4 == 0 {
            writeln!(pos, "   GP2:\n\tUF : {}, UT : {},\t\n\tJ1=     0.000  mm", bases[b].0, tools[t].0).unwrap();
        }
        pos.push_str("};\n");
    }
    let text = format!(
        "/PROG  WELDCELL\n/ATTR\nOWNER\t\t= MNEDITOR;\nCOMMENT\t\t= \"P[1] X = 5 mm\";\nPROG_SIZE\t= 0;\nCREATE\t\t= DATE 26-01-12  TIME 10:00:00;\nMODIFIED\t= DATE 26-01-12  TIME 10:00:00;\nFILE_NAME\t= ;\nVERSION\t\t= 0;\nLINE_COUNT\t= {line};\nMEMORY_SIZE\t= 0;\nPROTECT\t\t= READ_WRITE;\nTCD:  STACK_SIZE\t= 0,\n      TASK_PRIORITY\t= 50,\n      TIME_SLICE\t= 0,\n      BUSY_LAMP_OFF\t= 0,\n      ABORT_REQUEST\t= 0,\n      PAUSE_REQUEST\t= 0;\nDEFAULT_GROUP\t= 1,1,*,*,*;\nCONTROL_CODE\t= 00000000 00000000;\n/APPL\n/MN\n{mn}/POS\n{pos}/END\n"
    );
    Sample {
        files: vec![ProgramFile { name: "weldcell.ls".into(), bytes: text.into_bytes() }],
        frames,
        failing: vec![format!("P[{}]", n + 1)],
        joints: HashMap::new(),
        seed_joints: None,
    }
}

/// Whether the controller, at joints `from`, solves the pose of `to` back to `to` (Newton on the
/// nominal model from `from`): no other solution of the pose lies nearer.
fn solved_back(set: &ParameterSet, tool: &Tool, from: &[f64; 6], to: &[f64; 6]) -> bool {
    let s = set.with_tool(tool.clone());
    let chain = s.nominal_chain();
    let target = chain.fk(&JointState::new(to));
    robocal::kinematics::ik_numeric::solve(&chain, &s.gravity(), &target, from, &Default::default())
        .is_ok_and(|sol| sol.joints().iter().zip(to).all(|(a, b)| (a - b).abs() < 1e-6))
}

/// The smallest singular value of the nominal TCP Jacobian at `q` (position rows in m/rad,
/// rotation rows scaled by 0.3 m): how far `q` is from a singularity.
fn conditioning(set: &ParameterSet, tool: &Tool, q: &[f64; 6]) -> f64 {
    let s = set.with_tool(tool.clone());
    let chain = s.nominal_chain();
    let h = 1e-6;
    let mut j = nalgebra::Matrix6::zeros();
    for k in 0..6 {
        let (mut a, mut b) = (*q, *q);
        a[k] += h;
        b[k] -= h;
        let fa = chain.fk(&JointState::new(&a));
        let fb = chain.fk(&JointState::new(&b));
        let dp = (fa.t - fb.t) / (2.0 * h);
        let dr = rotation_vector(&(fa.r * fb.r.transpose())) / (2.0 * h) * 0.3;
        for r in 0..3 {
            j[(r, k)] = dp[r];
            j[(3 + r, k)] = dr[r];
        }
    }
    j.singular_values().min()
}

/// A URScript program on the UR10: a random walk of joint positions (each pose the nominal TCP of
/// its step), poses inline and in variables, movej joint lists, a movec, two TCPs and payloads,
/// an offset through pose_trans, comments and strings with pose-like text.
pub fn urscript(seed: u64, n: usize) -> Sample {
    let set = ur10_set();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let tcps = [
        tool([0.0, 0.0, 180.0], [0.0, 0.0, 0.0], 2.1, [0.0, 0.0, 70.0]),
        tool([50.0, 0.0, 120.0], [0.0, 30.0, 0.0], 1.4, [20.0, 0.0, 50.0]),
    ];
    let start = [0.0, -100.0, 100.0, -90.0, -90.0, 0.0].map(|v| v * DEG);
    let mut q = start;
    let mut text = String::from("def weldcell():\n  # movel(p[0.1, 0.2, 0.3, 0, 0, 0]) commented out\n");
    let mut joints = HashMap::new();
    let mut line = 2;
    let emit = |text: &mut String, s: String, line: &mut usize| {
        text.push_str(&s);
        text.push('\n');
        *line += 1;
    };
    let pose = |f: &Frame, short: bool| -> String {
        let v = rotation_vector(&f.r);
        let vals = [f.t.x, f.t.y, f.t.z, v.x, v.y, v.z];
        let s: Vec<String> = vals
            .iter()
            .map(|x| {
                let s = format!("{x:.9}");
                match (short, s.strip_prefix("0."), s.strip_prefix("-0.")) {
                    (true, Some(rest), _) => format!(".{rest}"),
                    (true, _, Some(rest)) => format!("-.{rest}"),
                    _ => s,
                }
            })
            .collect();
        format!("p[{}]", s.join(", "))
    };
    let mut tcp = 0;
    emit(&mut text, "  set_tcp(p[0.0, 0.0, 0.18, 0.0, 0.0, 0.0])".into(), &mut line);
    emit(&mut text, "  set_payload(2.1, [0.0, 0.0, 0.07])".into(), &mut line);
    let qd: Vec<String> = start.iter().map(|v| format!("{v:.9}")).collect();
    emit(&mut text, format!("  home = [{}]", qd.join(", ")), &mut line);
    emit(&mut text, "  movej(home, a=1.4, v=1.05)".into(), &mut line);
    let mut k = 0;
    while k < n {
        // The next step of the walk, away from the wrist, elbow and shoulder singularities.
        let next = loop {
            let mut c = q;
            for v in c.iter_mut() {
                *v += rng.random_range(-12.0..12.0) * DEG;
            }
            let ok = c[4].abs() > 20.0 * DEG
                && c[4].abs() < 160.0 * DEG
                && c[2].abs() > 45.0 * DEG
                && c[2].abs() < 150.0 * DEG
                && c[1] < -20.0 * DEG
                && c[1] > -160.0 * DEG
                // The walk stays inside the ±360° of the base and wrist joints (a long program's
                // unbounded walk would leave them: targets no controller reaches).
                && [0, 3, 5].iter().all(|&j| c[j].abs() < 300.0 * DEG);
            if ok
                && conditioning(&set, &tcps[tcp], &c) > 0.12
                && conditioning(&set, &tcps[1 - tcp], &c) > 0.12
                && solved_back(&set, &tcps[tcp], &q, &c)
                && solved_back(&set, &tcps[1 - tcp], &q, &c)
            {
                break c;
            }
        };
        q = next;
        if k % 40 == 20 {
            tcp = 1 - tcp;
            let t = &tcps[tcp];
            let v = rotation_vector(&Frame::from_xyzabc(&t.tcp).r);
            emit(
                &mut text,
                format!(
                    "  set_tcp(p[{:.6}, {:.6}, {:.6}, {:.9}, {:.9}, {:.9}])",
                    t.tcp[0], t.tcp[1], t.tcp[2], v.x, v.y, v.z
                ),
                &mut line,
            );
            emit(
                &mut text,
                format!("  set_payload({}, [{:.3}, {:.3}, {:.3}])", t.mass, t.com.x, t.com.y, t.com.z),
                &mut line,
            );
        }
        let f = nominal_pose(&set, &tcps[tcp], &Frame::identity(), &q);
        match rng.random_range(0..10) {
            0..=3 => {
                let l = line + 1;
                emit(&mut text, format!("  movel({}, a=1.2, v=0.25, r=0.002)", pose(&f, k % 3 == 0)), &mut line);
                joints.insert((l, "movel (inline)".to_string()), q.to_vec());
            }
            4..=5 => {
                let name = format!("wp_{k}");
                let l = line + 1;
                emit(&mut text, format!("  global {name} = {}  # p[1, 2, 3, 4, 5, 6]", pose(&f, false)), &mut line);
                emit(&mut text, format!("  movel({name}, a=1.2, v=0.25)"), &mut line);
                emit(
                    &mut text,
                    format!("  movel(pose_trans({name}, p[0, 0, -0.05, 0, 0, 0]), a=1.2, v=0.1)"),
                    &mut line,
                );
                emit(&mut text, format!("  movel({name}, a=1.2, v=0.25)"), &mut line);
                joints.insert((l, name), q.to_vec());
            }
            6 => {
                let l = line + 1;
                emit(&mut text, format!("  movej({}, a=1.4, v=1.05)", pose(&f, false)), &mut line);
                joints.insert((l, "movej (inline)".to_string()), q.to_vec());
            }
            7 => {
                let q2 = loop {
                    let mut c = q;
                    for v in c.iter_mut() {
                        *v += rng.random_range(-5.0..5.0) * DEG;
                    }
                    if c[4].abs() > 20.0 * DEG
                        && c[2].abs() > 45.0 * DEG
                        && conditioning(&set, &tcps[tcp], &c) > 0.12
                        && solved_back(&set, &tcps[tcp], &q, &c)
                    {
                        break c;
                    }
                };
                let f2 = nominal_pose(&set, &tcps[tcp], &Frame::identity(), &q2);
                let l = line + 1;
                emit(
                    &mut text,
                    format!("  movec({}, {}, a=1.2, v=0.1, r=0, mode=0)", pose(&f, false), pose(&f2, false)),
                    &mut line,
                );
                joints.insert((l, "movec (inline, via point)".to_string()), q.to_vec());
                joints.insert((l, "movec (inline, end point)".to_string()), q2.to_vec());
                q = q2;
                k += 1;
            }
            _ => {
                let qd: Vec<String> = q.iter().map(|v| format!("{v:.9}")).collect();
                emit(&mut text, format!("  movej([{}], a=1.4, v=1.05)", qd.join(", ")), &mut line);
            }
        }
        k += 1;
    }
    emit(&mut text, "  textmsg(\"done: movel(p[1,2,3,4,5,6])\")".into(), &mut line);
    // Out of reach, on purpose.
    emit(&mut text, "  movel(p[3.0, 0.0, 0.3, 0.0, 3.1416, 0.0], a=1.2, v=0.25)".into(), &mut line);
    text.push_str("end\n");
    Sample {
        files: vec![ProgramFile { name: "weldcell.script".into(), bytes: text.into_bytes() }],
        frames: GivenFrames::default(),
        failing: vec!["movel (inline)".into()],
        joints,
        seed_joints: Some(start.to_vec()),
    }
}
