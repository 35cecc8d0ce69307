//! ABB RAPID: `robtarget` and `jointtarget` declarations (`CONST`, `PERS`, `VAR`, one-dimensional
//! arrays included) and robtargets written inline in motion instructions, read with the
//! `tooldata` and `wobjdata` the modules declare.
//!
//! ```text
//! CONST robtarget p10:=[[515,0,712],[0.5,0,0.866025,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
//! PERS tooldata gun:=[TRUE,[[30,0,210],[0.92388,0,0.382683,0]],[2.5,[0,0,80],[1,0,0,0],0,0,0]];
//! PERS wobjdata table:=[FALSE,TRUE,"",[[600,-200,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
//! MoveL p10, v200, z5, gun\WObj:=table;
//! MoveJ [[600,0,400],[0,0,1,0],[0,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v500, z50, gun;
//! ```
//!
//! A robtarget is `[[x, y, z] mm, [q1 (w), q2, q3, q4], [cf1, cf4, cf6, cfx], [eax_a … eax_f]]`:
//! its confdata picks the branch (cfx) and the whole turns of axes 1, 4 and 6 (quadrants), and the
//! compensated pose is written with the confdata of the compensated joints. External axes are
//! kept byte for byte. A named target takes the tool and work object of the motions that use it
//! (`MoveL`, `MoveJ`, `MoveC`, their `DO`/`AO`/`GO`/`Sync` forms, `TriggL/J/C`, `ArcL/C`; the tool
//! is the last positional argument, the work object `\WObj`, default `wobj0`); a target used
//! through `Offs(p10, …)` or `RelTool(p10, …)` is compensated as written (the offset is added by
//! the controller, uncompensated). Joint targets take the tool of their `MoveAbsJ`.
//! Not compensated (marked `! robocal: NOT COMPENSATED: …`): targets no motion uses (their tool and
//! work object are unknown), targets used with two different tools or work objects, values that
//! are expressions, stationary tools and moving work objects.

use super::lex::{self, Edit, Lines, Syntax, Tok, Token};
use super::{
    Declared, Dialect, Kind, Parsed, Posture, ProgramError, ProgramFile, Ref, Solution, Style, Target, tool_of,
};
use crate::domain::pose::{frame_from_parts_noted, quaternion_near};
use crate::kinematics::{Branch, Confdata, Frame, Tool};
use crate::units::{DEG, MM};
use nalgebra::Vector3;

const SYNTAX: Syntax = Syntax { comment: b'!', ident_extra: &[], quotes: b"\"" };

/// Motions with one robtarget (the first positional argument).
const LINEAR: &[&str] = &[
    "movel",
    "movej",
    "moveldo",
    "movejdo",
    "movelao",
    "movejao",
    "movelgo",
    "movejgo",
    "movelsync",
    "movejsync",
    "triggl",
    "triggj",
    "trigglios",
    "triggjios",
    "arcl",
    "arclstart",
    "arclend",
    "spotl",
    "spotj",
];
/// Motions with two robtargets (circle point, end point).
const CIRCULAR: &[&str] =
    &["movec", "movecdo", "movecao", "movecgo", "movecsync", "triggc", "arcc", "arccstart", "arccend"];
/// Motions to a jointtarget.
const ABSOLUTE: &[&str] = &["moveabsj"];

pub(crate) struct Rapid;

/// A parsed aggregate value.
#[derive(Clone, Debug)]
enum Item {
    Num {
        span: (usize, usize),
        value: f64,
    },
    Word {
        text: String,
        span: (usize, usize),
    },
    List {
        items: Vec<Item>,
        span: (usize, usize),
        line: usize,
    },
    /// Anything else (an expression): its span.
    Other {
        span: (usize, usize),
    },
}

impl Item {
    fn span(&self) -> Option<(usize, usize)> {
        match self {
            Item::Num { span, .. } | Item::List { span, .. } | Item::Other { span } | Item::Word { span, .. } => {
                Some(*span)
            }
        }
    }
}

/// How a motion uses a named target.
#[derive(Clone, Debug, PartialEq)]
struct Use {
    tool: String,
    wobj: String,
    line: usize,
}

struct Reader<'a> {
    file: &'a str,
    bytes: &'a [u8],
    toks: Vec<Token>,
    /// Data declared in this module: lower-case name → line.
    declared: std::cell::RefCell<std::collections::HashMap<String, usize>>,
}

impl<'a> Reader<'a> {
    fn err(&self, i: usize, msg: impl Into<String>) -> ProgramError {
        let line = self.toks.get(i).or(self.toks.last()).map_or(1, |t| t.line);
        ProgramError::new(self.file, line, msg)
    }

    fn text(&self, i: usize) -> String {
        lex::latin1(self.toks[i].text(self.bytes))
    }

    /// The aggregate or value starting at token `i`; `i` ends on the token after it.
    fn item(&self, i: &mut usize) -> Result<Item, ProgramError> {
        let toks = &self.toks;
        let Some(t) = toks.get(*i) else { return Err(self.err(*i, "the value ends early")) };
        if t.is(b'[') {
            let (start, line) = (t.start, t.line);
            *i += 1;
            let mut items = Vec::new();
            loop {
                match toks.get(*i) {
                    None => return Err(ProgramError::new(self.file, line, "a '[' is not closed")),
                    Some(t) if t.is(b']') && items.is_empty() => {
                        *i += 1;
                        return Ok(Item::List { items, span: (start, t.end), line });
                    }
                    _ => {}
                }
                items.push(self.item(i)?);
                match toks.get(*i) {
                    Some(t) if t.is(b',') => *i += 1,
                    Some(t) if t.is(b']') => {
                        *i += 1;
                        return Ok(Item::List { items, span: (start, t.end), line });
                    }
                    Some(t) if t.is(b';') => {
                        return Err(ProgramError::new(self.file, t.line, "a '[' is not closed before ';'"));
                    }
                    _ => {
                        return Err(
                            self.err(*i, format!("expected ',' or ']' in the value, found '{}'", self.text(*i)))
                        );
                    }
                }
            }
        }
        // A scalar: the tokens up to the next ',' ']' or ';' at depth 0.
        let first = *i;
        let mut depth = 0i32;
        while let Some(t) = toks.get(*i) {
            match t.kind {
                Tok::Punct(b'(' | b'[' | b'{') => depth += 1,
                Tok::Punct(b')' | b']' | b'}') if depth > 0 => depth -= 1,
                Tok::Punct(b',' | b']' | b';') if depth == 0 => break,
                _ => {}
            }
            *i += 1;
        }
        if *i == first {
            return Err(self.err(first, "a value is missing"));
        }
        let (start, end) = (toks[first].start, toks[*i - 1].end);
        let part = &toks[first..*i];
        let signed = part.len() == 2 && (part[0].is(b'-') || part[0].is(b'+')) && part[1].kind == Tok::Number;
        if (part.len() == 1 && part[0].kind == Tok::Number || signed)
            && let Some(value) = lex::number(&self.bytes[start..end])
        {
            return Ok(Item::Num { span: (start, end), value });
        }
        if part.len() == 1 && part[0].kind == Tok::Ident {
            return Ok(Item::Word { text: self.text(first).to_ascii_lowercase(), span: (start, end) });
        }
        Ok(Item::Other { span: (start, end) })
    }
}

/// The numbers of a list of `n` literals, or `None` (a wrong shape), or `Some(Err)` when one is an
/// expression.
fn numbers(item: &Item, n: usize) -> Option<Result<lex::Literals, String>> {
    let Item::List { items, .. } = item else { return None };
    if items.len() != n {
        return None;
    }
    let mut out = Vec::with_capacity(n);
    for it in items {
        match it {
            Item::Num { span, value, .. } => out.push((*span, *value)),
            Item::List { .. } => return None,
            _ => return Some(Err("its value is not written as literal numbers (an expression)".into())),
        }
    }
    Some(Ok(out))
}

fn list(item: &Item) -> Option<&[Item]> {
    if let Item::List { items, .. } = item { Some(items) } else { None }
}

fn word(item: &Item) -> Option<&str> {
    if let Item::Word { text, .. } = item { Some(text) } else { None }
}

/// `[[x,y,z],[q1,q2,q3,q4]]` → a frame (mm, quaternion normalised).
fn pose_of(item: &Item) -> Option<Result<(Frame, Option<String>), String>> {
    let items = list(item)?;
    if items.len() != 2 {
        return None;
    }
    let p = match numbers(&items[0], 3)? {
        Ok(p) => p,
        Err(e) => return Some(Err(e)),
    };
    let q = match numbers(&items[1], 4)? {
        Ok(q) => q,
        Err(e) => return Some(Err(e)),
    };
    Some(
        frame_from_parts_noted([p[0].1, p[1].1, p[2].1], None, Some([q[0].1, q[1].1, q[2].1, q[3].1]))
            .map_err(|e| format!("{}: {}", e.path, e.reason)),
    )
}

/// The statement tokens from `i` to its `;` (exclusive); `i` ends after the `;`.
fn statement(r: &Reader, i: &mut usize) -> Result<(usize, usize), ProgramError> {
    let start = *i;
    let mut depth = 0i32;
    while let Some(t) = r.toks.get(*i) {
        match t.kind {
            Tok::Punct(b'(' | b'[' | b'{') => depth += 1,
            Tok::Punct(b')' | b']' | b'}') => depth -= 1,
            Tok::Punct(b';') if depth <= 0 => {
                *i += 1;
                return Ok((start, *i - 1));
            }
            _ => {}
        }
        *i += 1;
    }
    Err(r.err(start, "the statement has no ';'"))
}

/// Split tokens [a, b) at the commas at depth 0.
fn split_args(toks: &[Token], a: usize, b: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut depth = 0i32;
    let mut s = a;
    for k in a..b {
        match toks[k].kind {
            Tok::Punct(b'(' | b'[' | b'{') => depth += 1,
            Tok::Punct(b')' | b']' | b'}') => depth -= 1,
            Tok::Punct(b',') if depth == 0 => {
                out.push((s, k));
                s = k + 1;
            }
            _ => {}
        }
    }
    out.push((s, b));
    out
}

/// Optional arguments: each one's lower-case name and its value's token range.
type Options = Vec<(String, (usize, usize))>;

/// An argument's positional part (before any `\Option`) and its options (name, value tokens).
fn positional_and_options(toks: &[Token], bytes: &[u8], a: usize, b: usize) -> ((usize, usize), Options) {
    let mut depth = 0i32;
    let mut cut = b;
    for k in a..b {
        match toks[k].kind {
            Tok::Punct(b'(' | b'[' | b'{') => depth += 1,
            Tok::Punct(b')' | b']' | b'}') => depth -= 1,
            Tok::Punct(b'\\') if depth == 0 => {
                cut = k;
                break;
            }
            _ => {}
        }
    }
    let mut options = Vec::new();
    let mut k = cut;
    while k < b {
        // `\Name` [ `:=` value ] up to the next `\` at depth 0.
        let name =
            toks.get(k + 1).filter(|t| t.kind == Tok::Ident).map(|t| lex::latin1(t.text(bytes)).to_ascii_lowercase());
        let mut end = k + 1;
        let mut depth = 0i32;
        while end < b {
            match toks[end].kind {
                Tok::Punct(b'(' | b'[' | b'{') => depth += 1,
                Tok::Punct(b')' | b']' | b'}') => depth -= 1,
                Tok::Punct(b'\\') if depth == 0 && end > k + 1 => break,
                _ => {}
            }
            end += 1;
        }
        if let Some(n) = name {
            let value_start = if end > k + 3 && toks[k + 2].is(b':') && toks[k + 3].is(b'=') { k + 4 } else { end };
            options.push((n, (value_start, end)));
        }
        k = end;
    }
    ((a, cut), options)
}

impl Dialect for Rapid {
    fn parse(&self, files: &[ProgramFile]) -> Result<Parsed, ProgramError> {
        let mut parsed = Parsed::default();
        // Named targets: (target index, lower-case base name) to give their uses' frames later.
        let mut named: Vec<(usize, String)> = Vec::new();
        let mut uses: std::collections::HashMap<String, Vec<Use>> = std::collections::HashMap::new();
        let mut named_sequence: Vec<String> = Vec::new();
        for (fi, f) in files.iter().enumerate() {
            let toks = lex::tokenize(&f.bytes, &SYNTAX, &f.name)?;
            let r = Reader { file: &f.name, bytes: &f.bytes, toks, declared: Default::default() };
            let mut i = 0;
            while i < r.toks.len() {
                let t = r.toks[i];
                if t.kind != Tok::Ident {
                    i += 1;
                    continue;
                }
                let w = r.text(i).to_ascii_lowercase();
                if matches!(w.as_str(), "const" | "pers" | "var") {
                    declaration(&r, fi, &mut i, &mut parsed, &mut named)?;
                    continue;
                }
                let next_is_call = r.toks.get(i + 1).is_some_and(|n| n.is(b'(') || n.is(b':') || n.is(b'.'));
                let prev_dot = i > 0 && r.toks[i - 1].is(b'.');
                let shape = if LINEAR.contains(&w.as_str()) {
                    Some(1)
                } else if CIRCULAR.contains(&w.as_str()) {
                    Some(2)
                } else if ABSOLUTE.contains(&w.as_str()) {
                    Some(0)
                } else {
                    None
                };
                match shape {
                    Some(n) if !next_is_call && !prev_dot => {
                        let name = r.text(i);
                        i += 1;
                        let (a, b) = statement(&r, &mut i)?;
                        motion(&r, fi, &name, n, a, b, &mut parsed, &mut uses, &mut named_sequence)?;
                    }
                    _ => i += 1,
                }
            }
        }
        // Named targets take the frames of the motions that use them.
        for (k, base_name) in &named {
            let t = &mut parsed.targets[*k];
            let joint = matches!(t.kind, Kind::Joints { .. });
            match uses.get(base_name) {
                None => {
                    let why = "no motion in these modules uses it: its tool and work object are unknown".to_string();
                    t.tool = Ref::Missing(why.clone());
                    t.base = Ref::Missing(why);
                }
                Some(us) => {
                    let first = &us[0];
                    let clash = us.iter().find(|u| u.tool != first.tool || (!joint && u.wobj != first.wobj));
                    if let Some(u) = clash {
                        let show = |u: &Use| {
                            if joint { u.tool.clone() } else { format!("{}\\WObj:={}", u.tool, u.wobj) }
                        };
                        t.problem.get_or_insert(format!(
                            "used with {} (line {}) and with {} (line {}): one value cannot serve both",
                            show(first),
                            first.line,
                            show(u),
                            u.line
                        ));
                    }
                    t.tool = tool_ref(&first.tool);
                    t.base = if joint { Ref::Given(Frame::identity()) } else { wobj_ref(&first.wobj) };
                }
            }
        }
        // The motion order for the sequence (RAPID targets carry their configuration; the order
        // only matters for poses without one, which RAPID does not have).
        let index: std::collections::HashMap<&str, Vec<usize>> =
            named.iter().fold(std::collections::HashMap::new(), |mut m, (k, n)| {
                m.entry(n.as_str()).or_default().push(*k);
                m
            });
        for n in &named_sequence {
            if let Some(ks) = index.get(n.as_str()) {
                parsed.sequence.extend(ks);
            }
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
                let hint = [t.values[3], t.values[4], t.values[5], t.values[6]];
                let q = quaternion_near(&pose.r, hint);
                for k in 0..4 {
                    out.push(Edit::replace(t.slots[3 + k], lex::trimmed(q[k], 9)));
                }
                if let Some(c) = s.confdata {
                    for (k, v) in [c.cf1, c.cf4, c.cf6, i32::from(c.cfx.cfx())].into_iter().enumerate() {
                        out.push(Edit::replace(t.slots[7 + k], v.to_string()));
                    }
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
        Edit::insert(at, format!(" ! robocal: NOT COMPENSATED: {}", lex::comment_text(why, 240)))
    }
}

fn tool_ref(name: &str) -> Ref<Tool> {
    if name == "tool0" { Ref::Given(Tool::flange()) } else { Ref::Named(name.to_string()) }
}

fn wobj_ref(name: &str) -> Ref<Frame> {
    if name == "wobj0" { Ref::Given(Frame::identity()) } else { Ref::Named(name.to_string()) }
}

/// A declaration at `i` (`CONST`/`PERS`/`VAR`, after an optional `LOCAL`/`TASK`).
fn declaration(
    r: &Reader,
    fi: usize,
    i: &mut usize,
    parsed: &mut Parsed,
    named: &mut Vec<(usize, String)>,
) -> Result<(), ProgramError> {
    let at = *i;
    let (a, b) = statement(r, i)?;
    let toks = &r.toks;
    if b < a + 3 || toks[a + 1].kind != Tok::Ident || toks[a + 2].kind != Tok::Ident {
        return Ok(()); // not a data declaration we read (or a syntax the controller will judge)
    }
    let ty = r.text(a + 1).to_ascii_lowercase();
    if !matches!(ty.as_str(), "robtarget" | "jointtarget" | "tooldata" | "wobjdata") {
        return Ok(());
    }
    let name = r.text(a + 2);
    let mut k = a + 3;
    let mut array = false;
    if toks.get(k).is_some_and(|t| t.is(b'{')) {
        array = true;
        while k < b && !toks[k].is(b'}') {
            k += 1;
        }
        k += 1;
    }
    if k >= b {
        return Ok(()); // no initial value
    }
    if !(toks[k].is(b':') && toks.get(k + 1).is_some_and(|t| t.is(b'='))) {
        return Err(r.err(k, format!("{ty} {name}: expected ':=' after the name")));
    }
    let mut v = k + 2;
    if !toks.get(v).is_some_and(|t| t.is(b'[')) {
        return Ok(()); // a computed value (CRobT(…), another constant): not a literal target
    }
    let value = r.item(&mut v)?;
    if v != b {
        return Err(r.err(v, format!("{ty} {name}: unexpected '{}' after the value", r.text(v))));
    }
    let line = toks[at].line;
    let key = name.to_ascii_lowercase();
    if let Some(first) = r.declared.borrow_mut().insert(key.clone(), line) {
        return Err(ProgramError::new(
            r.file,
            line,
            format!("{name} is declared twice in this module (lines {first} and {line})"),
        ));
    }
    match ty.as_str() {
        "robtarget" | "jointtarget" => {
            let joint = ty == "jointtarget";
            let mut found = Vec::new();
            collect(r, &value, &name, array, joint, &mut found)?;
            for (elem_name, item) in found {
                let target =
                    if joint { jointtarget(r, fi, &elem_name, &item)? } else { robtarget(r, fi, &elem_name, &item)? };
                named.push((parsed.targets.len(), key.clone()));
                parsed.targets.push(target);
            }
        }
        "tooldata" if !array => {
            let value = tooldata(&value).ok_or_else(|| {
                ProgramError::new(
                    r.file,
                    line,
                    format!("tooldata {name}: expected [robhold,[[x,y,z],[q1,q2,q3,q4]],[mass,[cx,cy,cz],[q1,q2,q3,q4],ix,iy,iz]]"),
                )
            })?;
            parsed.tools.insert(key, Declared { value, file: fi, line });
        }
        "wobjdata" if !array => {
            let value = wobjdata(&value).ok_or_else(|| {
                ProgramError::new(
                    r.file,
                    line,
                    format!("wobjdata {name}: expected [robhold,ufprog,\"ufmec\",[[x,y,z],[q1,q2,q3,q4]],[[x,y,z],[q1,q2,q3,q4]]]"),
                )
            })?;
            parsed.bases.insert(key, Declared { value, file: fi, line });
        }
        _ => {}
    }
    Ok(())
}

/// The robtargets (or jointtargets) of a value: itself, or an array's elements named `name{k}`
/// (`name{k,m}` for two dimensions).
fn collect(
    r: &Reader,
    value: &Item,
    name: &str,
    array: bool,
    joint: bool,
    out: &mut Vec<(String, Item)>,
) -> Result<(), ProgramError> {
    if !array {
        out.push((name.to_string(), value.clone()));
        return Ok(());
    }
    elements(r, value, name, &mut Vec::new(), joint, out)
}

fn elements(
    r: &Reader,
    value: &Item,
    name: &str,
    index: &mut Vec<usize>,
    joint: bool,
    out: &mut Vec<(String, Item)>,
) -> Result<(), ProgramError> {
    let Item::List { items, line, .. } = value else {
        let line = value.span().map_or(1, |s| Lines::new(r.bytes).line_of(s.0));
        return Err(ProgramError::new(r.file, line, format!("{name}: an array's value must be a list")));
    };
    let leaf = |it: &Item| {
        list(it).is_some_and(|l| {
            l.len() == if joint { 2 } else { 4 }
                && list(&l[0]).is_some_and(|x| x.iter().all(|y| !matches!(y, Item::List { .. })))
        })
    };
    for (k, it) in items.iter().enumerate() {
        index.push(k + 1);
        let elem = format!("{name}{{{}}}", index.iter().map(|i| i.to_string()).collect::<Vec<_>>().join(","));
        if leaf(it) {
            out.push((elem, it.clone()));
        } else if list(it).is_some() {
            elements(r, it, name, index, joint, out)?;
        } else {
            let what = if joint { "jointtarget" } else { "robtarget" };
            return Err(ProgramError::new(r.file, *line, format!("{elem}: not a {what}")));
        }
        index.pop();
    }
    Ok(())
}

const ROBTARGET_SHAPE: &str = "[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[eax_a,eax_b,eax_c,eax_d,eax_e,eax_f]]";

/// A robtarget value → a pose target (its tool and work object filled in later).
fn robtarget(r: &Reader, fi: usize, name: &str, item: &Item) -> Result<Target, ProgramError> {
    let (span, line) = match item {
        Item::List { span, line, .. } => (*span, *line),
        other => {
            let line = other.span().map_or(1, |s| Lines::new(r.bytes).line_of(s.0));
            return Err(ProgramError::new(r.file, line, format!("robtarget {name}: expected {ROBTARGET_SHAPE}")));
        }
    };
    let shape_err = || ProgramError::new(r.file, line, format!("robtarget {name}: expected {ROBTARGET_SHAPE}"));
    let items = list(item).filter(|l| l.len() == 4).ok_or_else(shape_err)?;
    let mut problem = None;
    let mut slots = Vec::new();
    let mut values = Vec::new();
    for (k, n) in [(0, 3), (1, 4), (2, 4)] {
        match numbers(&items[k], n).ok_or_else(shape_err)? {
            Ok(v) => {
                slots.extend(v.iter().map(|x| x.0));
                values.extend(v.iter().map(|x| x.1));
            }
            Err(e) => problem = Some(e),
        }
    }
    if list(&items[3]).is_none_or(|l| l.len() != 6) {
        return Err(shape_err());
    }
    let mut notes = Vec::new();
    let mut kind = Kind::Joints { q: Vec::new() };
    if problem.is_none() {
        let p = [values[0], values[1], values[2]];
        let q = [values[3], values[4], values[5], values[6]];
        let cd: Vec<f64> = values[7..11].to_vec();
        match frame_from_parts_noted(p, None, Some(q)) {
            Err(e) => problem = Some(format!("orientation: {}", e.reason)),
            Ok((pose, note)) => {
                notes.extend(note);
                if cd.iter().any(|v| v.fract() != 0.0 || v.abs() > 1e6) {
                    problem = Some("confdata must be whole numbers".into());
                } else {
                    match u8::try_from(cd[3] as i64).ok().and_then(Branch::new) {
                        None => problem = Some(format!("confdata cfx must be 0-7, found {}", cd[3])),
                        Some(cfx) => {
                            let posture = Posture::Confdata(Confdata {
                                cf1: cd[0] as i32,
                                cf4: cd[1] as i32,
                                cf6: cd[2] as i32,
                                cfx,
                            });
                            kind = Kind::Pose { pose, posture };
                        }
                    }
                }
            }
        }
    }
    if problem.is_some() {
        kind = Kind::Pose { pose: Frame::identity(), posture: Posture::Nearest };
    }
    Ok(Target {
        file: fi,
        name: name.to_string(),
        line,
        kind,
        tool: Ref::Missing(String::new()),
        payload: None,
        base: Ref::Missing(String::new()),
        slots,
        values,
        extent: span,
        problem,
        notes,
        style: Style::Plain,
    })
}

/// A jointtarget value `[[j1..j6],[e1..e6]]` (deg) → a joint target.
fn jointtarget(r: &Reader, fi: usize, name: &str, item: &Item) -> Result<Target, ProgramError> {
    let (span, line) = match item {
        Item::List { span, line, .. } => (*span, *line),
        other => {
            let line = other.span().map_or(1, |s| Lines::new(r.bytes).line_of(s.0));
            return Err(ProgramError::new(r.file, line, format!("jointtarget {name}: expected [[j1,…,j6],[e1,…,e6]]")));
        }
    };
    let shape_err = || ProgramError::new(r.file, line, format!("jointtarget {name}: expected [[j1,…,j6],[e1,…,e6]]"));
    let items = list(item).filter(|l| l.len() == 2).ok_or_else(shape_err)?;
    if list(&items[1]).is_none_or(|l| l.len() != 6) {
        return Err(shape_err());
    }
    let (slots, values, problem) = match numbers(&items[0], 6).ok_or_else(shape_err)? {
        Ok(v) => (v.iter().map(|x| x.0).collect(), v.iter().map(|x| x.1).collect::<Vec<_>>(), None),
        Err(e) => (Vec::new(), Vec::new(), Some(e)),
    };
    Ok(Target {
        file: fi,
        name: name.to_string(),
        line,
        kind: Kind::Joints { q: values.iter().map(|v| v * DEG).collect() },
        tool: Ref::Missing(String::new()),
        payload: None,
        base: Ref::Given(Frame::identity()),
        slots,
        values,
        extent: span,
        problem,
        notes: Vec::new(),
        style: Style::Plain,
    })
}

/// `tooldata` → the tool, or why it cannot be used; `None` for a wrong shape.
fn tooldata(item: &Item) -> Option<Result<Tool, String>> {
    let l = list(item).filter(|l| l.len() == 3)?;
    let robhold = word(&l[0])?;
    let frame = pose_of(&l[1])?;
    let load = list(&l[2]).filter(|x| x.len() == 6)?;
    let (mass, com) = match (&load[0], numbers(&load[1], 3)?) {
        (Item::Num { value, .. }, Ok(c)) => (*value, Vector3::new(c[0].1, c[1].1, c[2].1) * MM),
        _ => return Some(Err("its load is not written as literal numbers".into())),
    };
    Some((|| {
        if robhold == "false" {
            return Err("a stationary tool (robhold FALSE): the robot holds the work object; not supported".into());
        }
        if robhold != "true" {
            return Err(format!("robhold must be TRUE or FALSE, found {robhold}"));
        }
        let (tcp, _) = frame?;
        if mass < 0.0 {
            return Err(format!("its load mass {mass} kg is negative (an undefined load): define it"));
        }
        let mut tool = tool_of(&tcp);
        tool.mass = mass;
        tool.com = com;
        Ok(tool)
    })())
}

/// `wobjdata` → its frame (user frame · object frame) in the base frame, or why it cannot be used.
fn wobjdata(item: &Item) -> Option<Result<Frame, String>> {
    let l = list(item).filter(|l| l.len() == 5)?;
    let robhold = word(&l[0])?;
    let ufprog = word(&l[1])?;
    let uframe = pose_of(&l[3])?;
    let oframe = pose_of(&l[4])?;
    Some((|| {
        if robhold == "true" {
            return Err("a work object held by the robot (stationary tool): not supported".into());
        }
        if ufprog == "false" {
            return Err("a moving user frame (ufprog FALSE, coordinated with a mechanical unit): not supported".into());
        }
        Ok(uframe?.0.compose(&oframe?.0))
    })())
}

/// A motion instruction's arguments (tokens a..b): its targets and the tool and work object.
#[allow(clippy::too_many_arguments)]
fn motion(
    r: &Reader,
    fi: usize,
    instruction: &str,
    targets: usize,
    a: usize,
    b: usize,
    parsed: &mut Parsed,
    uses: &mut std::collections::HashMap<String, Vec<Use>>,
    sequence: &mut Vec<String>,
) -> Result<(), ProgramError> {
    let toks = &r.toks;
    let line = toks.get(a).map_or_else(|| toks[a.saturating_sub(1)].line, |t| t.line);
    let mut positional: Vec<(usize, usize)> = Vec::new();
    let mut wobj = "wobj0".to_string();
    for (s, e) in split_args(toks, a, b) {
        let ((ps, pe), options) = positional_and_options(toks, r.bytes, s, e);
        if pe > ps {
            positional.push((ps, pe));
        }
        for (name, (vs, ve)) in options {
            if name == "wobj" && ve == vs + 1 && toks[vs].kind == Tok::Ident {
                wobj = r.text(vs).to_ascii_lowercase();
            }
        }
    }
    let Some(&(ts, te)) = positional.last() else { return Ok(()) };
    let tool = if te == ts + 1 && toks[ts].kind == Tok::Ident {
        r.text(ts).to_ascii_lowercase()
    } else {
        return Ok(()); // a tool given by an expression: nothing to associate
    };
    let n = targets.max(1);
    for (k, &(ps, pe)) in positional.iter().take(n).enumerate() {
        let first = toks[ps];
        if first.is(b'[') {
            let mut v = ps;
            let item = r.item(&mut v)?;
            if v != pe {
                return Err(r.err(v, format!("{instruction}: unexpected '{}' after the target", r.text(v))));
            }
            let label = if targets == 2 {
                format!("{instruction} (inline, {})", if k == 0 { "circle point" } else { "end point" })
            } else {
                format!("{instruction} (inline)")
            };
            let mut t =
                if targets == 0 { jointtarget(r, fi, &label, &item)? } else { robtarget(r, fi, &label, &item)? };
            t.tool = tool_ref(&tool);
            t.base = if targets == 0 { Ref::Given(Frame::identity()) } else { wobj_ref(&wobj) };
            parsed.sequence.push(parsed.targets.len());
            parsed.targets.push(t);
        } else if first.kind == Tok::Ident {
            // A name, an array element `name{…}`, or a function of a name: Offs(p10, …), RelTool(p10, …).
            let name = if pe > ps + 1 && toks[ps + 1].is(b'(') {
                if pe > ps + 3 && toks[ps + 2].kind == Tok::Ident && (toks[ps + 3].is(b',') || toks[ps + 3].is(b'{')) {
                    r.text(ps + 2)
                } else {
                    continue;
                }
            } else {
                r.text(ps)
            };
            let key = name.to_ascii_lowercase();
            uses.entry(key.clone()).or_default().push(Use { tool: tool.clone(), wobj: wobj.clone(), line });
            sequence.push(key);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::program::{FilterOptions, read};

    fn files(text: &str) -> Vec<ProgramFile> {
        vec![ProgramFile { name: "t.mod".into(), bytes: text.as_bytes().to_vec() }]
    }

    #[test]
    fn named_inline_array_and_joint_targets_are_read_with_their_frames() {
        let text = "MODULE T\n\
            PERS tooldata gun:=[TRUE,[[0,0,100],[1,0,0,0]],[2,[0,0,50],[1,0,0,0],0,0,0]];\n\
            TASK PERS wobjdata table:=[FALSE,TRUE,\"\",[[500,0,0],[1,0,0,0]],[[0,0,10],[1,0,0,0]]];\n\
            CONST robtarget p1:=[[10,20,30],[0,0,1,0],[0,0,-1,1],[9E+09,9E9,9E9,9E9,9E9,9E9]]; ! p2:=[[1,2,3]]\n\
            LOCAL CONST robtarget path{2}:=[[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],\n\
                [[4,5,6],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];\n\
            CONST jointtarget home:=[[0,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n\
            VAR robtarget p9:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n\
            VAR robtarget here:=CRobT(\\Tool:=gun\\WObj:=table);\n\
            PROC main()\n\
              MoveAbsJ home\\NoEOffs, v1000, fine, tool0;\n\
              MoveL p1, v100, z10, gun\\WObj:=table;\n\
              MoveL Offs(path{1},0,0,10), v100, z10, gun\\WObj:=table;\n\
              MoveJ [[7,8,9],[1,0,0,0],[0,0,0,1],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, tool0;\n\
              TPWrite \"MoveL p1, v100, z10, tool0;\";\n\
            ENDPROC\nENDMODULE\n";
        let (_, t) = read(&files(text), &FilterOptions::default()).unwrap();
        let names: Vec<&str> = t.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(names, ["p1", "path{1}", "path{2}", "home", "p9", "MoveJ (inline)"]);
        let p1 = &t[0];
        assert_eq!(p1.line, 4);
        assert_eq!(p1.branch, Branch::new(1));
        let pose = p1.pose.unwrap();
        assert!((pose.t - Vector3::new(0.010, 0.020, 0.030)).norm() < 1e-15);
        // q = (0, 0, 1, 0): 180° about y.
        assert!((pose.r[(0, 0)] + 1.0).abs() < 1e-15 && (pose.r[(2, 2)] + 1.0).abs() < 1e-15);
        let tool = p1.tool.clone().unwrap();
        assert!((tool.tcp[2] - 0.1).abs() < 1e-15 && tool.mass == 2.0);
        assert!((p1.base.clone().unwrap().t - Vector3::new(0.5, 0.0, 0.01)).norm() < 1e-15);
        // Used through Offs: the array's frames, for every element.
        assert!(t[1].tool.is_ok() && t[1].base.is_ok() && t[2].tool.is_ok());
        // Never used: frames unknown.
        assert!(t[4].tool.as_ref().unwrap_err().contains("no motion"));
        assert_eq!(t[3].joints.as_ref().unwrap()[4], 30.0 * DEG);
        assert_eq!(t[3].tool.clone().unwrap(), Tool::flange());
        assert_eq!(t[5].line, 14);
    }

    #[test]
    fn malformed_values_name_their_line() {
        let e = |text: &str| match read(&files(text), &FilterOptions::default()) {
            Err(crate::domain::program::FilterError::Program(e)) => e,
            other => panic!("{other:?}"),
        };
        let err = e("MODULE T\nCONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0,0]];\nENDMODULE\n");
        assert_eq!(err.line, 2);
        assert!(err.message.contains("robtarget p1") && err.message.contains("cf1"), "{}", err.message);
        let err =
            e("MODULE T\n\nCONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9];\nENDMODULE\n");
        assert_eq!(err.line, 3, "{err}");
        let err = e("MODULE T\nPROC m()\n  MoveL p1, v100, z10, tool0\nENDPROC\nENDMODULE\n");
        assert!(err.line >= 3, "{err}");
        // An expression is the target's own problem, not the program's.
        let (_, t) = read(
            &files("MODULE T\nCONST robtarget p1:=[[x0+1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\nENDMODULE\n"),
            &FilterOptions::default(),
        )
        .unwrap();
        assert!(t[0].problem.as_deref().unwrap().contains("expression"));
    }
}
