//! KUKA KRL: a program is a `.src` (the motions) and its `.dat` (the points), rewritten together.
//!
//! ```text
//! DECL E6POS XP1={X 510.5,Y -12.3,Z 742.0,A 0.0,B 90.0,C 0.0,S 2,T 35,E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}
//! DECL FDAT FP1={TOOL_NO 1,BASE_NO 2,IPO_FRAME #BASE,POINT2[] " ",TQ_STATE FALSE}
//! DECL E6AXIS XHOME={A1 0.0,A2 -90.0,A3 90.0,A4 0.0,A5 30.0,A6 0.0,E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}
//! ```
//!
//! Targets: `E6POS`, `POS` and `FRAME` values (X, Y, Z mm; A, B, C deg, ZY'X'', the rotation
//! `Rz(A)·Ry(B)·Rx(C)`), in the `.dat` (declarations, array elements `P[3]={…}`) or inline in a
//! `.src` motion (`PTP`, `LIN`, `CIRC` and their spline forms `SPTP`, `SLIN`, `SCIRC`); joint
//! targets `E6AXIS` and `AXIS` (A1…A6 deg). Status `S` and turn `T` pick the solution and are
//! written for the compensated joints: S bit 0 the wrist centre behind axis 1 (KUKA's overhead
//! area), bit 1 the wrist centre behind the lower arm (the elbow's other side), bit 2 axis 5
//! negative; T bit j axis j+1 negative; the other bits are kept. A pose without S and T (a
//! `FRAME`, a bare `POS`) takes the solution nearest the motion before it.
//!
//! Tool and base of a motion, in the `.src`'s text order: `FDAT_ACT=F…` (the inline forms' tool and
//! base numbers, `TOOL_NO`/`BASE_NO` from the `.dat`), `$TOOL=TOOL_DATA[n]`, `$BASE=BASE_DATA[n]`,
//! `BAS(#TOOL,n)`, `BAS(#BASE,n)`, an inline frame `$TOOL={X …}`, a `FRAME` of the `.dat`, or
//! `$NULLFRAME`/`$WORLD`. `TOOL_DATA[n]` and `BASE_DATA[n]` live in the robot's `$config.dat`: they
//! are given by number (the command line's `--tool n:…`, `--base n:…`); number 0 is the flange and
//! the world. `$ROBROOT` is taken as the world. A point of the `.dat` that no motion uses takes
//! the tool and base of its own `FDAT` (`XP3` ↔ `FP3`), as the inline forms store them.

use std::collections::{BTreeMap, HashMap};

use super::lex::{self, Edit, Lines, Syntax, Tok, Token};
use super::{
    Declared, Dialect, Kind, Parsed, Posture, ProgramError, ProgramFile, Ref, Solution, Style, Target, frame_mm_deg,
    tool_of,
};
use crate::domain::pose::zyx_deg_near;
use crate::kinematics::{Branch, Frame, Tool};
use crate::units::{DEG, MM};

const SYNTAX: Syntax = Syntax { comment: b';', ident_extra: b"$#", quotes: b"\"'" };

pub(crate) struct Krl;

const POSE_TYPES: &[&str] = &["e6pos", "pos", "frame"];
const JOINT_TYPES: &[&str] = &["e6axis", "axis"];
const MOTIONS: &[&str] = &["ptp", "lin", "circ", "sptp", "slin", "scirc"];

/// A value of an aggregate's element.
#[derive(Clone, Debug)]
enum Value {
    Num {
        span: (usize, usize),
        value: f64,
    },
    /// A `'B…'` bit string: its span and digits.
    Bits {
        span: (usize, usize),
        value: u32,
        digits: usize,
    },
    /// A nested aggregate (not read).
    Agg,
    Other,
}

/// A parsed `{…}` aggregate: its elements by lower-case key, and its span.
#[derive(Clone, Debug)]
struct Agg {
    items: Vec<(String, Value)>,
    span: (usize, usize),
    line: usize,
}

impl Agg {
    fn get(&self, key: &str) -> Option<&Value> {
        self.items.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }

    fn num(&self, key: &str) -> Option<((usize, usize), f64)> {
        match self.get(key)? {
            Value::Num { span, value } => Some((*span, *value)),
            _ => None,
        }
    }
}

/// One file's tokens grouped by line (KRL statements are one line each).
struct Reader<'a> {
    file: &'a str,
    bytes: &'a [u8],
    toks: Vec<Token>,
}

impl Reader<'_> {
    fn text(&self, i: usize) -> String {
        lex::latin1(self.toks[i].text(self.bytes)).to_ascii_lowercase()
    }

    /// The statements: token index ranges of each line.
    fn statements(&self) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        let mut s = 0;
        for k in 1..=self.toks.len() {
            if k == self.toks.len() || self.toks[k].line != self.toks[s].line {
                out.push((s, k));
                s = k;
            }
        }
        out
    }

    /// The aggregate `{…}` at token `i` (within `end`); `i` ends after the `}`.
    fn agg(&self, i: &mut usize, end: usize) -> Result<Agg, ProgramError> {
        let open = self.toks[*i];
        let err = |m: String| ProgramError::new(self.file, open.line, m);
        *i += 1;
        let mut items = Vec::new();
        loop {
            let Some(t) = self.toks.get(*i).filter(|_| *i < end) else {
                return Err(err("a '{' is not closed on its line".into()));
            };
            if t.is(b'}') {
                *i += 1;
                return Ok(Agg { items, span: (open.start, t.end), line: open.line });
            }
            if t.kind != Tok::Ident {
                return Err(err(format!(
                    "expected a component name in the aggregate, found '{}'",
                    lex::latin1(t.text(self.bytes))
                )));
            }
            let mut key = self.text(*i);
            *i += 1;
            if self.toks.get(*i).is_some_and(|t| t.is(b'[')) && self.toks.get(*i + 1).is_some_and(|t| t.is(b']')) {
                key.push_str("[]");
                *i += 2;
            }
            let value = if self.toks.get(*i).is_some_and(|t| t.is(b'{')) {
                {
                    self.agg(i, end)?;
                    Value::Agg
                }
            } else {
                let first = *i;
                let mut depth = 0i32;
                while *i < end {
                    let t = self.toks[*i];
                    match t.kind {
                        Tok::Punct(b'(' | b'[' | b'{') => depth += 1,
                        Tok::Punct(b')' | b']') if depth > 0 => depth -= 1,
                        Tok::Punct(b'}') if depth > 0 => depth -= 1,
                        Tok::Punct(b',' | b'}') if depth == 0 => break,
                        _ => {}
                    }
                    *i += 1;
                }
                if *i == first {
                    return Err(err(format!("component {} has no value", key.to_ascii_uppercase())));
                }
                let (s, e) = (self.toks[first].start, self.toks[*i - 1].end);
                let part = &self.toks[first..*i];
                let operand = |t: &Token| matches!(t.kind, Tok::Number | Tok::Ident | Tok::Str(_));
                if part.windows(2).any(|w| operand(&w[0]) && operand(&w[1])) {
                    return Err(err(format!(
                        "component {}: '{}' is not one value (a ',' missing?)",
                        key.to_ascii_uppercase(),
                        lex::latin1(&self.bytes[s..e])
                    )));
                }
                let text = &self.bytes[s..e];
                let numeric = part.len() == 1 && part[0].kind == Tok::Number
                    || part.len() == 2 && (part[0].is(b'-') || part[0].is(b'+')) && part[1].kind == Tok::Number;
                if numeric && let Some(value) = lex::number(text) {
                    Value::Num { span: (s, e), value }
                } else if part.len() == 1
                    && part[0].kind == Tok::Str(b'\'')
                    && text.len() > 3
                    && (text[1] == b'B' || text[1] == b'b')
                {
                    let digits = &text[2..text.len() - 1];
                    match u32::from_str_radix(&lex::latin1(digits), 2) {
                        Ok(value) => Value::Bits { span: (s, e), value, digits: digits.len() },
                        Err(_) => Value::Other,
                    }
                } else {
                    Value::Other
                }
            };
            items.push((key, value));
            match self.toks.get(*i).filter(|_| *i < end) {
                Some(t) if t.is(b',') => *i += 1,
                Some(t) if t.is(b'}') => {}
                _ => return Err(err("expected ',' or '}' in the aggregate".into())),
            }
        }
    }
}

/// The frame of an aggregate's X, Y, Z, A, B, C (`None` when one is missing or not a number).
fn frame_of(agg: &Agg) -> Option<Frame> {
    let v: Vec<f64> = ["x", "y", "z", "a", "b", "c"].iter().map(|k| agg.num(k).map(|x| x.1)).collect::<Option<_>>()?;
    Some(frame_mm_deg([v[0], v[1], v[2]], [v[3], v[4], v[5]]))
}

/// A status or turn value: its slot and how it is written (`'B…'` digits, or `None` for a number).
fn status(agg: &Agg, key: &str) -> Option<((usize, usize), u32, Option<usize>)> {
    match agg.get(key)? {
        Value::Num { span, value } if value.fract() == 0.0 && *value >= 0.0 && *value < 65536.0 => {
            Some((*span, *value as u32, None))
        }
        Value::Bits { span, value, digits } => Some((*span, *value, Some(*digits))),
        _ => None,
    }
}

/// A pose or joint target from an aggregate (`type_` one of [`POSE_TYPES`], [`JOINT_TYPES`]).
fn target(file: usize, name: &str, type_: &str, agg: &Agg, reader: &Reader) -> Result<Target, ProgramError> {
    let mut t = Target {
        file,
        name: name.to_string(),
        line: agg.line,
        kind: Kind::Joints { q: Vec::new() },
        tool: Ref::Missing(String::new()),
        payload: None,
        base: Ref::Missing(String::new()),
        slots: Vec::new(),
        values: Vec::new(),
        extent: agg.span,
        problem: None,
        notes: Vec::new(),
        style: Style::Plain,
    };
    if JOINT_TYPES.contains(&type_) {
        for k in 1..=6 {
            match agg.num(&format!("a{k}")) {
                Some((span, v)) => {
                    t.slots.push(span);
                    t.values.push(v);
                }
                None => {
                    t.problem =
                        Some(format!("A{k} is missing or not a number: a partial axis value cannot be recomputed"));
                    break;
                }
            }
        }
        t.kind = Kind::Joints { q: t.values.iter().map(|v| v * DEG).collect() };
        return Ok(t);
    }
    for k in ["x", "y", "z", "a", "b", "c"] {
        match agg.num(k) {
            Some((span, v)) => {
                t.slots.push(span);
                t.values.push(v);
            }
            None => {
                let what = if agg.get(k).is_some() { "not a number" } else { "missing (a partial aggregate)" };
                t.problem = Some(format!("{} is {what}", k.to_ascii_uppercase()));
            }
        }
    }
    if agg
        .items
        .iter()
        .any(|(k, _)| !matches!(k.as_str(), "x" | "y" | "z" | "a" | "b" | "c" | "s" | "t") && !k.starts_with('e'))
    {
        let bad: Vec<String> = agg.items.iter().map(|(k, _)| k.to_ascii_uppercase()).collect();
        return Err(ProgramError::new(
            reader.file,
            agg.line,
            format!("{name}: not a {} value ({})", type_.to_ascii_uppercase(), bad.join(",")),
        ));
    }
    let s = status(agg, "s");
    let tt = status(agg, "t");
    if agg.get("s").is_some() && s.is_none() || agg.get("t").is_some() && tt.is_none() {
        t.problem.get_or_insert("S and T must be whole numbers or 'B…' bit strings".into());
    }
    let mut style_s = None;
    let mut style_t = None;
    if let Some((span, _, digits)) = s {
        style_s = Some((t.slots.len(), digits));
        t.slots.push(span);
        t.values.push(f64::from(s.unwrap().1));
    }
    if let Some((span, _, digits)) = tt {
        style_t = Some((t.slots.len(), digits));
        t.slots.push(span);
        t.values.push(f64::from(tt.unwrap().1));
    }
    t.style = Style::Krl { s: style_s, t: style_t };
    let posture = match (s, tt) {
        (Some((_, sv, _)), turn) => {
            let branch = Branch::from_flags(sv & 1 != 0, sv & 2 != 0, sv & 4 != 0);
            let mut ranges = [None; 6];
            if let Some((_, tv, _)) = turn {
                let tau = std::f64::consts::TAU;
                for (j, r) in ranges.iter_mut().enumerate() {
                    *r = Some(if tv & (1 << j) != 0 { (-tau, 0.0) } else { (0.0, tau) });
                }
            }
            Posture::Turns { branch, ranges }
        }
        (None, _) => Posture::Nearest,
    };
    t.kind = Kind::Pose { pose: frame_of(agg).unwrap_or_else(Frame::identity), posture };
    Ok(t)
}

/// The tool or base a `.src` motion runs with.
#[derive(Clone, Debug, PartialEq)]
enum Active {
    Number(String),
    Name(String),
    Inline(Frame),
    Identity,
    Missing(String),
}

impl Active {
    fn tool(&self) -> Ref<Tool> {
        match self {
            Active::Number(n) | Active::Name(n) => Ref::Named(n.clone()),
            Active::Inline(f) => Ref::Given(tool_of(f)),
            Active::Identity => Ref::Given(Tool::flange()),
            Active::Missing(w) => Ref::Missing(w.clone()),
        }
    }

    fn base(&self) -> Ref<Frame> {
        match self {
            Active::Number(n) | Active::Name(n) => Ref::Named(n.clone()),
            Active::Inline(f) => Ref::Given(*f),
            Active::Identity => Ref::Given(Frame::identity()),
            Active::Missing(w) => Ref::Missing(w.clone()),
        }
    }

    fn number(n: &str) -> Active {
        if n.trim_start_matches('0').is_empty() { Active::Identity } else { Active::Number(n.to_string()) }
    }

    fn show(&self) -> String {
        match self {
            Active::Number(n) => format!("[{n}]"),
            Active::Name(n) => n.to_ascii_uppercase(),
            Active::Inline(_) => "an inline frame".into(),
            Active::Identity => "$NULLFRAME".into(),
            Active::Missing(_) => "none".into(),
        }
    }
}

/// A `.dat` declaration of interest.
struct DatDecl {
    type_: String,
    agg: Agg,
}

/// One `.src` + `.dat` pair (either may be absent).
#[derive(Default)]
struct Pair {
    src: Option<usize>,
    dat: Option<usize>,
}

impl Dialect for Krl {
    fn parse(&self, files: &[ProgramFile]) -> Result<Parsed, ProgramError> {
        let mut pairs: BTreeMap<String, Pair> = BTreeMap::new();
        for (i, f) in files.iter().enumerate() {
            let lower = f.name.to_ascii_lowercase();
            let (stem, ext) = lower.rsplit_once('.').unwrap_or((lower.as_str(), ""));
            let stem = stem.rsplit(['/', '\\']).next().unwrap_or(stem).to_string();
            let p = pairs.entry(stem).or_default();
            let slot = if ext == "dat" || ext != "src" && is_data_list(&f.bytes) { &mut p.dat } else { &mut p.src };
            if slot.is_some() {
                return Err(ProgramError::new(
                    &f.name,
                    0,
                    "two files of the same name and kind: give each .src/.dat pair once",
                ));
            }
            *slot = Some(i);
        }
        let mut parsed = Parsed::default();
        for pair in pairs.values() {
            parse_pair(files, pair, &mut parsed)?;
        }
        Ok(parsed)
    }

    fn render(&self, t: &Target, s: &Solution) -> Vec<Edit> {
        let mut out = Vec::with_capacity(t.slots.len());
        match &t.kind {
            Kind::Pose { .. } => {
                let pose = s.pose.expect("a pose target's solution has a pose");
                for k in 0..3 {
                    out.push(Edit::replace(t.slots[k], lex::trimmed(pose.t[k] / MM, 4)));
                }
                let abc = zyx_deg_near(&pose.r, [t.values[3], t.values[4], t.values[5]]);
                for k in 0..3 {
                    out.push(Edit::replace(t.slots[3 + k], lex::trimmed(abc[k], 6)));
                }
                let Style::Krl { s: ss, t: ts } = &t.style else { return out };
                let write = |slot: usize, digits: Option<usize>, v: u32| match digits {
                    None => Edit::replace(t.slots[slot], v.to_string()),
                    Some(d) => Edit::replace(t.slots[slot], format!("'B{v:0d$b}'")),
                };
                if let (Some((slot, digits)), Some(c)) = (ss, s.confdata) {
                    let old = t.values[*slot] as u32;
                    let b = c.cfx;
                    let v = (old & !7)
                        | u32::from(b.shoulder_back())
                        | u32::from(b.elbow_behind()) << 1
                        | u32::from(b.wrist_negative()) << 2;
                    out.push(write(*slot, *digits, v));
                }
                if let Some((slot, digits)) = ts {
                    let old = t.values[*slot] as u32;
                    let mut v = old & !63;
                    for (j, q) in s.joints.iter().enumerate().take(6) {
                        if *q < 0.0 {
                            v |= 1 << j;
                        }
                    }
                    out.push(write(*slot, *digits, v));
                }
            }
            Kind::Joints { .. } => {
                for (k, q) in s.joints.iter().enumerate().take(t.slots.len()) {
                    out.push(Edit::replace(t.slots[k], lex::trimmed(q / DEG, 6)));
                }
            }
        }
        out
    }

    fn mark(&self, bytes: &[u8], lines: &Lines, t: &Target, why: &str) -> Edit {
        let at = lines.end_of_line(bytes, t.extent.1.saturating_sub(1));
        Edit::insert(at, format!(" ; robocal: NOT COMPENSATED: {}", lex::comment_text(why, 240)))
    }
}

/// Whether a file without a `.src`/`.dat` extension is a data list (starts with `DEFDAT`).
fn is_data_list(bytes: &[u8]) -> bool {
    lex::latin1(&bytes[..bytes.len().min(4096)])
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with(';') && !l.starts_with('&'))
        .is_some_and(|l| l.to_ascii_uppercase().starts_with("DEFDAT"))
}

/// An error in a value of the `.dat`, with the name of what is declared (`XP2: component Y: …`).
fn named(mut e: ProgramError, name: &str) -> ProgramError {
    e.message = format!("{name}: {}", e.message);
    e
}

/// A `.src` + `.dat` pair read in three steps: the `.dat`'s declarations, the `.src`'s tools,
/// bases and motions in text order, then the `.dat`'s points as targets with the tool and base of
/// the motions that use them.
fn parse_pair(files: &[ProgramFile], pair: &Pair, parsed: &mut Parsed) -> Result<(), ProgramError> {
    let dat = read_dat(files, pair)?;
    let src = match pair.src {
        Some(s) => read_src(files, s, &dat, parsed)?,
        None => SrcUses::new(dat.decls.len()),
    };
    let decl_target = dat_targets(pair, &dat, &src, parsed)?;
    for s in src.sequence {
        match s {
            Ok(d) => parsed.sequence.extend(decl_target[d]),
            Err(i) => parsed.sequence.push(i),
        }
    }
    Ok(())
}

/// The FDAT values a `.dat` declares: its `TOOL_NO` and `BASE_NO`, each where given.
type Fdat = (Option<String>, Option<String>);

/// What a `.dat` declares.
struct Dat<'a> {
    /// Its reader (none without a `.dat`).
    reader: Option<Reader<'a>>,
    /// Its points and frames by name (as written), in order.
    decls: Vec<(String, DatDecl)>,
    /// Its FDATs by lower-case name.
    fdats: HashMap<String, Fdat>,
    /// Lower-case name → index in `decls`.
    index: HashMap<String, usize>,
}

/// Reads the pair's `.dat`: its declarations of interest by name, in order; a name declared twice
/// is an error.
fn read_dat<'a>(files: &'a [ProgramFile], pair: &Pair) -> Result<Dat<'a>, ProgramError> {
    let mut dat = Dat { reader: None, decls: Vec::new(), fdats: HashMap::new(), index: HashMap::new() };
    let Some(d) = pair.dat else { return Ok(dat) };
    let f = &files[d];
    let r = Reader { file: &f.name, bytes: &f.bytes, toks: lex::tokenize(&f.bytes, &SYNTAX, &f.name)? };
    let mut arrays: HashMap<String, String> = HashMap::new();
    for (a, b) in r.statements() {
        let mut k = a;
        while k < b && matches!(r.text(k).as_str(), "decl" | "global" | "const") && r.toks[k].kind == Tok::Ident {
            k += 1;
        }
        if k + 1 >= b || r.toks[k].kind != Tok::Ident {
            continue;
        }
        let first = r.text(k);
        let interesting = |t: &str| POSE_TYPES.contains(&t) || JOINT_TYPES.contains(&t) || t == "fdat";
        if interesting(&first) && r.toks[k + 1].kind == Tok::Ident {
            let name = lex::latin1(r.toks[k + 1].text(r.bytes));
            let lname = name.to_ascii_lowercase();
            let mut i = k + 2;
            if r.toks.get(i).is_some_and(|t| t.is(b'[')) && i < b {
                arrays.insert(lname, first);
                continue;
            }
            if !(i < b && r.toks[i].is(b'=')) {
                continue;
            }
            i += 1;
            if !(i < b && r.toks[i].is(b'{')) {
                return Err(ProgramError::new(r.file, r.toks[k].line, format!("{name}: expected '{{' after '='")));
            }
            let agg = r.agg(&mut i, b).map_err(|e| named(e, &name))?;
            if i != b {
                return Err(ProgramError::new(
                    r.file,
                    r.toks[k].line,
                    format!("{name}: unexpected text after the value"),
                ));
            }
            if first == "fdat" {
                let num = |key: &str| agg.num(key).map(|(_, v)| format!("{v}"));
                dat.fdats.insert(lname, (num("tool_no"), num("base_no")));
            } else {
                dat.decls.push((name, DatDecl { type_: first, agg }));
            }
        } else if r.toks[k + 1].is(b'[') {
            // An array element: NAME[i] = {…} (or NAME[i,j]).
            let Some(type_) = arrays.get(&first).cloned() else { continue };
            let mut i = k + 2;
            while i < b && !r.toks[i].is(b']') {
                i += 1;
            }
            if i + 2 >= b || !r.toks[i + 1].is(b'=') || !r.toks[i + 2].is(b'{') {
                continue;
            }
            let index = lex::latin1(&r.bytes[r.toks[k + 1].end..r.toks[i].start]);
            let name = format!("{}[{}]", lex::latin1(r.toks[k].text(r.bytes)), index.replace(' ', ""));
            let mut j = i + 2;
            let agg = r.agg(&mut j, b).map_err(|e| named(e, &name))?;
            if type_ != "fdat" {
                dat.decls.push((name, DatDecl { type_, agg }));
            }
        }
    }
    for (k, (n, d)) in dat.decls.iter().enumerate() {
        if let Some(first) = dat.index.insert(n.to_ascii_lowercase(), k) {
            return Err(ProgramError::new(
                r.file,
                d.agg.line,
                format!("{n} is declared twice (lines {} and {})", dat.decls[first].1.agg.line, d.agg.line),
            ));
        }
    }
    dat.reader = Some(r);
    Ok(dat)
}

/// What the `.src` says about the `.dat`'s declarations and its own inline targets.
struct SrcUses {
    /// Per declaration: the tool and base of each motion to it, with the motion's line.
    uses: Vec<Vec<(Active, Active, usize)>>,
    /// FRAME names set as `$TOOL`, with the first line that does.
    frame_tools: HashMap<String, usize>,
    /// FRAME names set as `$BASE`, with the first line that does.
    frame_bases: HashMap<String, usize>,
    /// The motions in text order: `Ok(declaration)` or `Err(inline target's index)`.
    sequence: Vec<Result<usize, usize>>,
}

impl SrcUses {
    fn new(n_decls: usize) -> SrcUses {
        SrcUses {
            uses: vec![Vec::new(); n_decls],
            frame_tools: HashMap::new(),
            frame_bases: HashMap::new(),
            sequence: Vec::new(),
        }
    }
}

/// Reads the `.src` (file `s`) in text order: the tool and base each statement sets, and the
/// motions with the tool and base active there. Inline targets go straight to `parsed`.
fn read_src(files: &[ProgramFile], s: usize, dat: &Dat, parsed: &mut Parsed) -> Result<SrcUses, ProgramError> {
    let mut out = SrcUses::new(dat.decls.len());
    let f = &files[s];
    let r = Reader { file: &f.name, bytes: &f.bytes, toks: lex::tokenize(&f.bytes, &SYNTAX, &f.name)? };
    let nothing =
        |what: &str| Active::Missing(format!("no {what} is set before it in the .src (FDAT_ACT, ${what} or BAS)"));
    let mut tool = nothing("TOOL");
    let mut base = nothing("BASE");
    for (a, b) in r.statements() {
        let first = r.text(a);
        let line = r.toks[a].line;
        let assign = b > a + 2 && r.toks[a + 1].is(b'=');
        match first.as_str() {
            "$tool" | "$base" if assign => {
                let is_tool = first == "$tool";
                let frames = if is_tool { &mut out.frame_tools } else { &mut out.frame_bases };
                let value = frame_assignment(&r, a, b, is_tool, frames)?;
                if is_tool { tool = value } else { base = value }
            }
            "fdat_act" if assign && b == a + 3 && r.toks[a + 2].kind == Tok::Ident => {
                let n = r.text(a + 2);
                match dat.fdats.get(&n) {
                    Some((t, bn)) => {
                        tool = t.as_deref().map_or_else(
                            || Active::Missing(format!("{} has no TOOL_NO", n.to_ascii_uppercase())),
                            Active::number,
                        );
                        base = bn.as_deref().map_or_else(
                            || Active::Missing(format!("{} has no BASE_NO", n.to_ascii_uppercase())),
                            Active::number,
                        );
                    }
                    None => {
                        let why = format!("FDAT {} (line {line}) is not in the .dat", n.to_ascii_uppercase());
                        tool = Active::Missing(why.clone());
                        base = Active::Missing(why);
                    }
                }
            }
            "bas" if b >= a + 6 && r.toks[a + 1].is(b'(') => {
                let which = r.text(a + 2);
                if r.toks[a + 3].is(b',') && r.toks[a + 4].kind == Tok::Number {
                    let n = lex::latin1(r.toks[a + 4].text(r.bytes));
                    match which.as_str() {
                        "#tool" => tool = Active::number(&n),
                        "#base" => base = Active::number(&n),
                        _ => {}
                    }
                }
            }
            m if MOTIONS.contains(&m) => {
                let at = Motion { r: &r, file: s, a, b, tool: &tool, base: &base };
                motion(&at, dat, &mut out, parsed)?;
            }
            _ => {}
        }
    }
    Ok(out)
}

/// The value of `$TOOL = …` or `$BASE = …` (statement `a..b`): an inline frame, `$NULLFRAME`
/// (or `$WORLD` for a base), a FRAME's name (recorded in `named` with its line), `TOOL_DATA[n]` /
/// `BASE_DATA[n]`, or unknown for any other expression.
fn frame_assignment(
    r: &Reader,
    a: usize,
    b: usize,
    is_tool: bool,
    named: &mut HashMap<String, usize>,
) -> Result<Active, ProgramError> {
    let first = r.text(a);
    let line = r.toks[a].line;
    let (data, null) =
        if is_tool { ("tool_data", ["$nullframe", ""]) } else { ("base_data", ["$nullframe", "$world"]) };
    let expression =
        || Active::Missing(format!("{} is set by an expression on line {line}", first.to_ascii_uppercase()));
    let rhs = a + 2;
    Ok(if r.toks[rhs].is(b'{') {
        let mut i = rhs;
        let agg = r.agg(&mut i, b)?;
        match frame_of(&agg) {
            Some(fr) if i == b => Active::Inline(fr),
            _ => expression(),
        }
    } else if r.toks[rhs].kind == Tok::Ident && b == rhs + 1 {
        let n = r.text(rhs);
        if null.contains(&n.as_str()) {
            Active::Identity
        } else {
            named.entry(n.clone()).or_insert(line);
            Active::Name(n)
        }
    } else if b == rhs + 4
        && r.text(rhs) == data
        && r.toks[rhs + 1].is(b'[')
        && r.toks[rhs + 2].kind == Tok::Number
        && r.toks[rhs + 3].is(b']')
    {
        Active::number(&lex::latin1(r.toks[rhs + 2].text(r.bytes)))
    } else {
        expression()
    })
}

/// A motion statement of the `.src`, with the tool and base active there.
struct Motion<'r, 'a> {
    r: &'r Reader<'a>,
    /// The `.src`'s file index.
    file: usize,
    /// The statement's first and one-past-last token.
    a: usize,
    b: usize,
    tool: &'r Active,
    base: &'r Active,
}

/// Reads one motion's target(s) (two for a CIRC): an inline aggregate becomes a target now; a
/// name (or `NAME[i]`) declared in the `.dat` is recorded as used with the active tool and base.
fn motion(m: &Motion, dat: &Dat, out: &mut SrcUses, parsed: &mut Parsed) -> Result<(), ProgramError> {
    let r = m.r;
    let (a, b) = (m.a, m.b);
    let first = r.text(a);
    let line = r.toks[a].line;
    let upper = first.to_ascii_uppercase();
    let mut i = a + 1;
    let count = if first.ends_with("circ") { 2 } else { 1 };
    for k in 0..count {
        if i >= b {
            return Err(ProgramError::new(r.file, line, format!("{upper}: a target is missing")));
        }
        if k > 0 {
            if !r.toks[i].is(b',') {
                return Err(ProgramError::new(r.file, line, format!("{upper}: expected ',' between its two targets")));
            }
            i += 1;
        }
        if i < b && r.toks[i].is(b'{') {
            let agg = r.agg(&mut i, b)?;
            let joint = agg.items.iter().any(|(key, _)| key == "a1");
            let type_ = if joint { "e6axis" } else { "e6pos" };
            let which = match (count, k) {
                (2, 0) => ", auxiliary point",
                (2, _) => ", end point",
                _ => "",
            };
            let mut t = target(m.file, &format!("{upper} (inline{which})"), type_, &agg, r)?;
            t.tool = m.tool.tool();
            t.base = if joint { Ref::Given(Frame::identity()) } else { m.base.base() };
            out.sequence.push(Err(parsed.targets.len()));
            parsed.targets.push(t);
        } else if i < b && r.toks[i].kind == Tok::Ident {
            let mut name = r.text(i);
            i += 1;
            if i < b && r.toks[i].is(b'[') {
                let open = i;
                while i < b && !r.toks[i].is(b']') {
                    i += 1;
                }
                if i >= b {
                    return Err(ProgramError::new(r.file, line, format!("{name}: a '[' is not closed")));
                }
                let index = lex::latin1(&r.bytes[r.toks[open].end..r.toks[i].start]);
                name = format!("{name}[{}]", index.replace(' ', "").to_ascii_lowercase());
                i += 1;
            }
            if let Some(&d) = dat.index.get(&name) {
                out.uses[d].push((m.tool.clone(), m.base.clone(), line));
                out.sequence.push(Ok(d));
            }
        } else {
            break;
        }
    }
    Ok(())
}

/// The `.dat`'s points become targets (FRAMEs used as `$TOOL` or `$BASE` become frames): each with
/// the tool and base of the motions that use it, else of its own FDAT. Returns each declaration's
/// target index.
fn dat_targets(pair: &Pair, dat: &Dat, src: &SrcUses, parsed: &mut Parsed) -> Result<Vec<Option<usize>>, ProgramError> {
    let mut decl_target: Vec<Option<usize>> = vec![None; dat.decls.len()];
    for (k, (name, d)) in dat.decls.iter().enumerate() {
        let lname = name.to_ascii_lowercase();
        let file = pair.dat.expect("declarations come from a .dat");
        let r = dat.reader.as_ref().expect("a .dat reader");
        if d.type_ == "frame" {
            let frame = frame_of(&d.agg).ok_or_else(|| format!("{name}: a FRAME needs X, Y, Z, A, B, C"));
            if src.frame_tools.contains_key(&lname) {
                let value = frame.clone().map(|f| tool_of(&f));
                parsed.tools.insert(lname.clone(), Declared { value, file, line: d.agg.line });
            }
            if src.frame_bases.contains_key(&lname) {
                parsed.bases.insert(lname.clone(), Declared { value: frame.clone(), file, line: d.agg.line });
            }
            if src.uses[k].is_empty() {
                continue; // a frame, not a point: no motion goes to it
            }
        }
        let mut t = target(file, name, &d.type_, &d.agg, r)?;
        let joint = matches!(t.kind, Kind::Joints { .. });
        let uses = &src.uses[k];
        match uses.first() {
            Some((tool, base, line)) => {
                if let Some((t2, b2, l2)) = uses.iter().find(|(t2, b2, _)| t2 != tool || !joint && b2 != base) {
                    t.problem.get_or_insert(format!(
                        "used with tool {} base {} (line {line}) and with tool {} base {} (line {l2}): one value cannot serve both",
                        tool.show(),
                        base.show(),
                        t2.show(),
                        b2.show()
                    ));
                }
                t.tool = tool.tool();
                t.base = if joint { Ref::Given(Frame::identity()) } else { base.base() };
            }
            None => (t.tool, t.base) = own_fdat(&lname, joint, &dat.fdats),
        }
        decl_target[k] = Some(parsed.targets.len());
        parsed.targets.push(t);
    }
    Ok(decl_target)
}

/// The tool and base of a point no motion uses, from its own FDAT (XP3 ↔ FP3, as the inline forms
/// store it); unknown without one. A joint target's base is the identity.
fn own_fdat(lname: &str, joint: bool, fdats: &HashMap<String, Fdat>) -> (Ref<Tool>, Ref<Frame>) {
    let fdat = lname.strip_prefix('x').map(|rest| format!("f{rest}"));
    let identity = || Ref::Given(Frame::identity());
    match fdat.as_ref().and_then(|f| fdats.get(f)) {
        Some((tn, bn)) => {
            let tool = tn
                .as_deref()
                .map_or_else(|| Ref::Missing("its FDAT has no TOOL_NO".into()), |n| Active::number(n).tool());
            let base = if joint {
                identity()
            } else {
                bn.as_deref()
                    .map_or_else(|| Ref::Missing("its FDAT has no BASE_NO".into()), |n| Active::number(n).base())
            };
            (tool, base)
        }
        None => {
            let why = "no motion of the .src uses it and it has no FDAT: its tool and base are unknown".to_string();
            let base = if joint { identity() } else { Ref::Missing(why.clone()) };
            (Ref::Missing(why), base)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::program::{FilterError, FilterOptions, read};

    fn pair(src: &str, dat: &str) -> Vec<ProgramFile> {
        vec![
            ProgramFile { name: "weld.src".into(), bytes: src.as_bytes().to_vec() },
            ProgramFile { name: "weld.dat".into(), bytes: dat.as_bytes().to_vec() },
        ]
    }

    const DAT: &str = "&ACCESS RVP\r\nDEFDAT WELD PUBLIC\r\n\
        DECL E6POS XP1={X 500.5,Y -10,Z 600,A 10,B 80,C -5,S 'B010',T 35,E1 0.0,E2 0.0}\r\n\
        DECL FDAT FP1={TOOL_NO 1,BASE_NO 2,IPO_FRAME #BASE,POINT2[] \" \",TQ_STATE FALSE}\r\n\
        DECL E6POS XP2={X 1,Y 2,Z 3,A 0,B 90,C 0,S 6,T 2}\r\n\
        DECL FDAT FP2={TOOL_NO 0,BASE_NO 0,IPO_FRAME #BASE}\r\n\
        DECL E6AXIS XHOME={A1 0,A2 -90,A3 90,A4 0,A5 30,A6 0,E1 0}\r\n\
        DECL FRAME GRIP={X 0,Y 0,Z 150,A 0,B 0,C 0}\r\n\
        DECL E6POS PATH[2]\r\n\
        PATH[1]={X 10,Y 20,Z 30,A 0,B 90,C 0,S 2,T 0}\r\n\
        ENDDAT\r\n";

    #[test]
    fn points_take_the_tool_and_base_of_their_motion() {
        let src = "DEF WELD( )\r\n\
            ;FOLD PTP P1 Vel=100 % PDAT1 Tool[1] Base[2];%{PE}\r\n\
            FDAT_ACT=FP1\r\n\
            PTP XP1\r\n\
            ;ENDFOLD\r\n\
            $TOOL=GRIP\r\n\
            $BASE=BASE_DATA[3]\r\n\
            LIN {X 100,Y 0,Z 300,A 0,B 90,C 0} C_DIS\r\n\
            LIN PATH[1]\r\n\
            PTP XHOME\r\n\
            END\r\n";
        let (_, t) = read(&pair(src, DAT), &FilterOptions::default()).unwrap();
        let names: Vec<&str> = t.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(names, ["LIN (inline)", "XP1", "XP2", "XHOME", "PATH[1]"]);
        let xp1 = &t[1];
        assert_eq!(xp1.line, 3);
        // S 'B010': the wrist centre behind the lower arm.
        assert_eq!(xp1.branch, Branch::new(2));
        // T 35 = 0b100011: axes 1, 2 and 6 negative.
        assert_eq!(xp1.ranges[0].unwrap().1, 0.0);
        assert_eq!(xp1.ranges[2].unwrap().0, 0.0);
        assert_eq!(xp1.ranges[5].unwrap().1, 0.0);
        assert!(xp1.tool.as_ref().unwrap_err().contains("tool '1'"), "{:?}", xp1.tool);
        let pose = xp1.pose.unwrap();
        assert!((pose.t.x - 0.5005).abs() < 1e-15);
        // XP2: unused, its FDAT says tool 0 and base 0.
        assert_eq!(t[2].tool.clone().unwrap(), Tool::flange());
        assert_eq!(t[2].base.clone().unwrap(), Frame::identity());
        // The inline LIN runs with the GRIP frame of the .dat as its tool, base 3 (not given).
        let tool = t[0].tool.clone().unwrap();
        assert!((tool.tcp[2] - 0.15).abs() < 1e-15);
        assert!(t[0].base.as_ref().unwrap_err().contains("'3'"));
        assert_eq!(t[0].line, 8);
        assert_eq!(t[3].joints.as_ref().unwrap()[4], 30.0 * DEG);
        assert_eq!(t[4].line, 10);
    }

    #[test]
    fn malformed_points_name_their_line() {
        let bad = DAT.replace("DECL E6POS XP2={X 1,Y 2,", "DECL E6POS XP2={X 1,Y 2 Z,");
        match read(&pair("DEF WELD( )\r\nEND\r\n", &bad), &FilterOptions::default()) {
            Err(FilterError::Program(e)) => {
                assert_eq!((e.file.as_str(), e.line), ("weld.dat", 5));
                assert_eq!(e.message, "XP2: component Y: '2 Z' is not one value (a ',' missing?)");
            }
            other => panic!("{other:?}"),
        }
        let open = "DEF WELD( )\r\nLIN {X 1,Y 2\r\nEND\r\n";
        match read(&pair(open, DAT), &FilterOptions::default()) {
            Err(FilterError::Program(e)) => assert_eq!((e.file.as_str(), e.line), ("weld.src", 2)),
            other => panic!("{other:?}"),
        }
    }
}
