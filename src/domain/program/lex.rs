//! Byte-level scanning shared by the program parsers: line numbers, a tokenizer parameterised by
//! each language's comment and identifier rules, literal numbers, and the edits that rewrite a
//! file. Everything works on bytes: programs may be ISO-8859-1 (RAPID, KRL), and only the bytes of
//! a target's numbers are ever replaced.

use super::ProgramError;

/// Where each line starts, to name lines (1-based) and find a line's end.
#[derive(Clone, Debug)]
pub struct Lines {
    starts: Vec<usize>,
    len: usize,
}

impl Lines {
    pub fn new(bytes: &[u8]) -> Self {
        let mut starts = vec![0];
        starts.extend(bytes.iter().enumerate().filter(|(_, b)| **b == b'\n').map(|(i, _)| i + 1));
        Lines { starts, len: bytes.len() }
    }

    /// The 1-based line of byte `offset`.
    pub fn line_of(&self, offset: usize) -> usize {
        self.starts.partition_point(|&s| s <= offset)
    }

    /// The offset just before the line terminator (`\n` or `\r\n`) of the line holding `offset`.
    pub fn end_of_line(&self, bytes: &[u8], offset: usize) -> usize {
        let line = self.line_of(offset);
        // The line's `\n`, or the end of the file.
        let mut end = if line < self.starts.len() { self.starts[line] - 1 } else { self.len };
        if end > 0 && bytes.get(end - 1) == Some(&b'\r') {
            end -= 1;
        }
        end
    }
}

/// Literal numbers as read: each one's byte span and value.
pub type Literals = Vec<((usize, usize), f64)>;

/// A token's kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tok {
    Ident,
    Number,
    /// A quoted string, its quote character.
    Str(u8),
    Punct(u8),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Token {
    pub kind: Tok,
    pub start: usize,
    pub end: usize,
    pub line: usize,
}

impl Token {
    pub fn text<'a>(&self, bytes: &'a [u8]) -> &'a [u8] {
        &bytes[self.start..self.end]
    }

    pub fn is(&self, c: u8) -> bool {
        self.kind == Tok::Punct(c)
    }
}

/// A language's lexical rules.
#[derive(Clone, Copy, Debug)]
pub struct Syntax {
    /// The comment character: the comment runs to the end of the line.
    pub comment: u8,
    /// Characters that may start or continue an identifier besides letters, digits and `_`.
    pub ident_extra: &'static [u8],
    /// String quote characters (a quote inside is doubled or backslash-escaped).
    pub quotes: &'static [u8],
}

/// Split `bytes` into tokens; comments and whitespace are skipped. Bytes above 0x7F (ISO-8859-1
/// letters in identifiers or comments) are identifier characters. A string left open at the end
/// of its line is an error naming the line.
pub fn tokenize(bytes: &[u8], syntax: &Syntax, file: &str) -> Result<Vec<Token>, ProgramError> {
    let mut out = Vec::with_capacity(bytes.len() / 4);
    let mut i = 0;
    let mut line = 1;
    let n = bytes.len();
    let ident_start = |c: u8| c.is_ascii_alphabetic() || c == b'_' || c >= 0x80 || syntax.ident_extra.contains(&c);
    while i < n {
        let c = bytes[i];
        if c == b'\n' {
            line += 1;
            i += 1;
        } else if c.is_ascii_whitespace() {
            i += 1;
        } else if c == syntax.comment {
            while i < n && bytes[i] != b'\n' {
                i += 1;
            }
        } else if syntax.quotes.contains(&c) {
            let start = i;
            i += 1;
            loop {
                if i >= n || bytes[i] == b'\n' {
                    return Err(ProgramError::new(file, line, "a string is not closed on its line"));
                }
                if bytes[i] == b'\\' && i + 1 < n && bytes[i + 1] != b'\n' {
                    i += 2;
                    continue;
                }
                if bytes[i] == c {
                    if i + 1 < n && bytes[i + 1] == c {
                        i += 2;
                        continue;
                    }
                    i += 1;
                    break;
                }
                i += 1;
            }
            out.push(Token { kind: Tok::Str(c), start, end: i, line });
        } else if c.is_ascii_digit() || (c == b'.' && i + 1 < n && bytes[i + 1].is_ascii_digit()) {
            let start = i;
            i = number_end(bytes, i);
            out.push(Token { kind: Tok::Number, start, end: i, line });
        } else if ident_start(c) {
            let start = i;
            i += 1;
            while i < n && (ident_start(bytes[i]) || bytes[i].is_ascii_digit()) {
                i += 1;
            }
            out.push(Token { kind: Tok::Ident, start, end: i, line });
        } else {
            out.push(Token { kind: Tok::Punct(c), start: i, end: i + 1, line });
            i += 1;
        }
    }
    Ok(out)
}

/// The end of an unsigned number literal starting at `i`: digits, an optional fraction and an
/// optional exponent (`9E9`, `9E+09`, `1.5e-3`, `.5`).
pub fn number_end(bytes: &[u8], mut i: usize) -> usize {
    let n = bytes.len();
    while i < n && bytes[i].is_ascii_digit() {
        i += 1;
    }
    if i < n && bytes[i] == b'.' {
        i += 1;
        while i < n && bytes[i].is_ascii_digit() {
            i += 1;
        }
    }
    if i < n && (bytes[i] == b'e' || bytes[i] == b'E') {
        let mut j = i + 1;
        if j < n && (bytes[j] == b'+' || bytes[j] == b'-') {
            j += 1;
        }
        if j < n && bytes[j].is_ascii_digit() {
            while j < n && bytes[j].is_ascii_digit() {
                j += 1;
            }
            i = j;
        }
    }
    i
}

/// A literal number (optionally signed, with spaces between the sign and the digits) as a finite
/// f64; `None` for anything else.
pub fn number(text: &[u8]) -> Option<f64> {
    let s = std::str::from_utf8(text).ok()?;
    let s: String = s.chars().filter(|c| !c.is_ascii_whitespace()).collect();
    let digits = s.trim_start_matches(['+', '-']);
    if digits.is_empty()
        || !digits.bytes().all(|b| b.is_ascii_digit() || matches!(b, b'.' | b'e' | b'E' | b'+' | b'-'))
        || !digits.as_bytes()[0].is_ascii_digit() && digits.as_bytes()[0] != b'.'
        || s.len() - digits.len() > 1
    {
        return None;
    }
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// Bytes as text for messages and reports: ISO-8859-1 (every byte is the code point of its value,
/// so UTF-8 files show their non-ASCII characters as two).
pub fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| b as char).collect()
}

/// Text made safe for a comment the filter writes into a program: one line, ASCII, bounded.
pub fn comment_text(s: &str, max: usize) -> String {
    let mut out: String =
        s.chars().map(|c| if c.is_ascii() && !c.is_ascii_control() { c } else { ' ' }).collect::<String>();
    out = out.split_whitespace().collect::<Vec<_>>().join(" ");
    if out.len() > max {
        out.truncate(max.saturating_sub(3));
        out.push_str("...");
    }
    out
}

/// One change to a file: replace `len` bytes at `at` by `text` (`len` 0: insert).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Edit {
    pub at: usize,
    pub len: usize,
    pub text: Vec<u8>,
}

impl Edit {
    pub fn replace(span: (usize, usize), text: impl Into<Vec<u8>>) -> Self {
        Edit { at: span.0, len: span.1 - span.0, text: text.into() }
    }

    pub fn insert(at: usize, text: impl Into<Vec<u8>>) -> Self {
        Edit { at, len: 0, text: text.into() }
    }
}

/// `bytes` with `edits` applied; the edits must not overlap (an insertion at the end of a
/// replaced span goes after it).
pub fn apply(bytes: &[u8], edits: &mut [Edit]) -> Vec<u8> {
    edits.sort_by_key(|e| (e.at, e.len));
    let mut out = Vec::with_capacity(bytes.len() + edits.iter().map(|e| e.text.len()).sum::<usize>());
    let mut at = 0;
    for e in edits.iter() {
        debug_assert!(e.at >= at, "overlapping edits at {}", e.at);
        let start = e.at.max(at);
        out.extend_from_slice(&bytes[at..start]);
        out.extend_from_slice(&e.text);
        at = (e.at + e.len).max(start);
    }
    out.extend_from_slice(&bytes[at..]);
    out
}

/// A number written with at most `decimals` decimals, trailing zeros dropped (`1.5`, `-2`, `0`;
/// never `-0`).
pub fn trimmed(v: f64, decimals: usize) -> String {
    let mut s = format!("{v:.decimals$}");
    if s.contains('.') {
        while s.ends_with('0') {
            s.pop();
        }
        if s.ends_with('.') {
            s.pop();
        }
    }
    if s == "-0" { "0".to_string() } else { s }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RAPID: Syntax = Syntax { comment: b'!', ident_extra: &[], quotes: b"\"" };

    #[test]
    fn tokens_skip_comments_and_keep_strings_whole() {
        let src = b"CONST num x:=9E+09; ! [1,2,3] not a target\r\nTPWrite \"a ! b\";\n";
        let t = tokenize(src, &RAPID, "m.mod").unwrap();
        let texts: Vec<String> = t.iter().map(|t| latin1(t.text(src))).collect();
        assert_eq!(texts, ["CONST", "num", "x", ":", "=", "9E+09", ";", "TPWrite", "\"a ! b\"", ";"]);
        assert_eq!(t[7].line, 2);
        let e = tokenize(b"a\nb \"open\n", &RAPID, "m.mod").unwrap_err();
        assert_eq!((e.line, e.file.as_str()), (2, "m.mod"));
    }

    #[test]
    fn numbers_are_literals_only() {
        assert_eq!(number(b"9E+09"), Some(9e9));
        assert_eq!(number(b"- 1.5"), Some(-1.5));
        assert_eq!(number(b".5"), Some(0.5));
        assert_eq!(number(b"-0.25e-2"), Some(-0.0025));
        for bad in [&b"inf"[..], b"nan", b"1e999", b"--1", b"x1", b"", b"-"] {
            assert_eq!(number(bad), None, "{}", latin1(bad));
        }
    }

    #[test]
    fn lines_and_edits_keep_every_other_byte() {
        let src = b"a 1\r\nb 22\nc 333";
        let l = Lines::new(src);
        assert_eq!((l.line_of(0), l.line_of(5), l.line_of(11)), (1, 2, 3));
        assert_eq!(l.end_of_line(src, 0), 3);
        assert_eq!(l.end_of_line(src, 6), 9);
        assert_eq!(l.end_of_line(src, 12), 15);
        let mut edits = vec![Edit::replace((7, 9), "7"), Edit::insert(3, " !x"), Edit::replace((2, 3), "4.5")];
        assert_eq!(apply(src, &mut edits), b"a 4.5 !x\r\nb 7\nc 333");
        assert_eq!(trimmed(1.50, 4), "1.5");
        assert_eq!(trimmed(-0.00001, 4), "0");
        assert_eq!(trimmed(12.0, 3), "12");
    }
}
