//! The `.npy` header, parsed by hand in bounded time.
//!
//! A header is the magic string `\x93NUMPY`, a format version (1.0, 2.0 or 3.0), the length of
//! the header text (2 bytes little-endian in version 1, 4 bytes in versions 2 and 3), and the
//! text: a Python dict literal with exactly the keys `descr`, `fortran_order` and `shape`,
//! padded with spaces and ended by a newline.
//!
//! The parser reads the small grammar of Python literals the format needs (strings, integers,
//! `True`, `False`, `None`, tuples, lists and dicts) in one pass, with the header at most
//! [`MAX_HEADER_BYTES`] long and literals nested at most [`MAX_NESTING`] deep, so that any
//! header, however malformed, gets its verdict in time linear in its length. Every error is one
//! line; what it quotes from the file has its control and non-printable characters escaped.

use std::io::Read;

/// The longest header text accepted, in bytes. NumPy itself refuses headers beyond 10 000 bytes
/// unless told otherwise; the headers of the arrays this crate exchanges are under 200.
pub const MAX_HEADER_BYTES: usize = 65_536;

/// The deepest nesting of brackets accepted in a header.
pub const MAX_NESTING: usize = 16;

/// The longest piece of a file quoted in an error message, in characters.
const QUOTE_CHARS: usize = 40;

/// What a header says, before the dtype is interpreted.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct RawHeader {
    /// `descr` when it is a string; `None` for a structured dtype (a list).
    pub descr: Option<String>,
    /// The description of a structured dtype, for messages.
    pub structured: String,
    pub fortran_order: bool,
    pub shape: Vec<usize>,
    /// Bytes before the data: magic, version, length and text.
    pub data_offset: u64,
}

/// Why a header was refused: a one-line reason, and whether the file ended inside it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum HeaderError {
    /// The file ends before the header does (`have` bytes in all).
    Truncated,
    /// The file does not start with the magic string.
    NotNpy,
    /// Anything else, as one line.
    Invalid(String),
    /// The file cannot be read.
    Io(String),
}

/// Reads and parses the header at the start of `reader`.
pub(super) fn read_header(reader: &mut impl Read) -> Result<RawHeader, HeaderError> {
    let mut prefix = [0u8; 8];
    read_exact(reader, &mut prefix[..6])?;
    if &prefix[..6] != b"\x93NUMPY" {
        return Err(HeaderError::NotNpy);
    }
    read_exact(reader, &mut prefix[6..8])?;
    let (major, minor) = (prefix[6], prefix[7]);
    let len_bytes = match major {
        1 => 2,
        2 | 3 => 4,
        _ => {
            return Err(HeaderError::Invalid(format!(
                "unsupported .npy format version {major}.{minor} (1.0, 2.0 and 3.0 are read)"
            )))
        }
    };
    let mut len_buf = [0u8; 4];
    read_exact(reader, &mut len_buf[..len_bytes])?;
    let text_len = u32::from_le_bytes(len_buf) as usize;
    if text_len > MAX_HEADER_BYTES {
        return Err(HeaderError::Invalid(format!(
            "the header is {text_len} bytes long, more than the {MAX_HEADER_BYTES} accepted"
        )));
    }
    let mut text = vec![0u8; text_len];
    read_exact(reader, &mut text)?;
    let text: String = if major == 3 {
        String::from_utf8(text).map_err(|_| {
            HeaderError::Invalid("the header of a version 3.0 file is not UTF-8".to_string())
        })?
    } else {
        // Versions 1 and 2 are latin-1: every byte is one character.
        text.iter().map(|&b| char::from(b)).collect()
    };
    let data_offset = (6 + 2 + len_bytes + text_len) as u64;
    let value = Parser::new(&text)
        .document()
        .map_err(HeaderError::Invalid)?;
    interpret(value, data_offset).map_err(HeaderError::Invalid)
}

fn read_exact(reader: &mut impl Read, buf: &mut [u8]) -> Result<(), HeaderError> {
    reader.read_exact(buf).map_err(|e| match e.kind() {
        std::io::ErrorKind::UnexpectedEof => HeaderError::Truncated,
        _ => HeaderError::Io(e.to_string()),
    })
}

/// A Python literal, as far as headers use them.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Value {
    Str(String),
    /// An integer, kept as written (it may not fit any machine type).
    Int(String),
    Bool(bool),
    None,
    Tuple(Vec<Value>),
    List(Vec<Value>),
    Dict(Vec<(Value, Value)>),
}

impl Value {
    fn kind(&self) -> &'static str {
        match self {
            Value::Str(_) => "a string",
            Value::Int(_) => "an integer",
            Value::Bool(_) => "a boolean",
            Value::None => "None",
            Value::Tuple(_) => "a tuple",
            Value::List(_) => "a list",
            Value::Dict(_) => "a dict",
        }
    }

    /// A short, escaped rendering for messages.
    fn quote(&self) -> String {
        let full = match self {
            Value::Str(s) => format!("'{s}'"),
            Value::Int(s) => s.clone(),
            Value::Bool(b) => if *b { "True" } else { "False" }.to_string(),
            Value::None => "None".to_string(),
            other => other.kind().to_string(),
        };
        escape_quoted(&full)
    }
}

/// `text` with control and non-printable characters escaped (`\n`, `\x1b`, `\u{85}`) and cut to
/// [`QUOTE_CHARS`] characters, so that a message quoting a file stays one printable line.
pub(super) fn escape_quoted(text: &str) -> String {
    let mut out = String::new();
    for (n, c) in text.chars().enumerate() {
        if n == QUOTE_CHARS {
            out.push('…');
            break;
        }
        push_escaped(&mut out, c);
    }
    out
}

/// `text` with control and non-printable characters escaped, at any length.
pub fn escape_all(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        push_escaped(&mut out, c);
    }
    out
}

fn push_escaped(out: &mut String, c: char) {
    match c {
        '\n' => out.push_str("\\n"),
        '\r' => out.push_str("\\r"),
        '\t' => out.push_str("\\t"),
        c if (c as u32) < 0x100 && (c.is_control() || c == '\u{a0}' || c == '\u{ad}') => {
            out.push_str(&format!("\\x{:02x}", c as u32));
        }
        c if c.is_control()
            || matches!(c, '\u{200b}'..='\u{200f}' | '\u{2028}'..='\u{202e}' | '\u{2066}'..='\u{2069}' | '\u{feff}') =>
        {
            out.push_str(&format!("\\u{{{:x}}}", c as u32));
        }
        c => out.push(c),
    }
}

/// A one-pass recursive-descent parser over the header text.
struct Parser<'a> {
    chars: std::iter::Peekable<std::str::CharIndices<'a>>,
    text: &'a str,
    depth: usize,
}

type Parsed<T> = Result<T, String>;

impl<'a> Parser<'a> {
    fn new(text: &'a str) -> Self {
        Parser {
            chars: text.char_indices().peekable(),
            text,
            depth: 0,
        }
    }

    fn position(&mut self) -> usize {
        self.chars.peek().map_or(self.text.len(), |&(i, _)| i)
    }

    fn skip_space(&mut self) {
        while let Some(&(_, c)) = self.chars.peek() {
            if c == ' ' || c == '\t' || c == '\n' || c == '\r' {
                self.chars.next();
            } else {
                break;
            }
        }
    }

    fn peek(&mut self) -> Option<char> {
        self.skip_space();
        self.chars.peek().map(|&(_, c)| c)
    }

    fn unexpected(&mut self, wanted: &str) -> String {
        let at = self.position();
        match self.peek() {
            None => format!("invalid .npy header: the text ends where {wanted} was expected"),
            Some(_) => {
                let rest = &self.text[self.position().max(at)..];
                format!(
                    "invalid .npy header: expected {wanted} at character {at}, found \"{}\"",
                    escape_quoted(rest)
                )
            }
        }
    }

    /// The whole text: one dict, then only spaces and newlines.
    fn document(mut self) -> Parsed<Value> {
        if self.peek() != Some('{') {
            return Err(self.unexpected("a dict '{'"));
        }
        let v = self.value()?;
        if self.peek().is_some() {
            return Err(self.unexpected("the end of the header after the dict"));
        }
        Ok(v)
    }

    fn value(&mut self) -> Parsed<Value> {
        match self.peek() {
            Some('{') => self
                .nested('}', |p| {
                    let key = p.value()?;
                    if p.peek() != Some(':') {
                        return Err(p.unexpected("':'"));
                    }
                    p.chars.next();
                    let value = p.value()?;
                    Ok((key, value))
                })
                .map(Value::Dict),
            Some('(') => {
                let (items, trailing_comma) = self.sequence(')')?;
                // `(x)` is x in parentheses; `(x,)` and `()` are tuples.
                if items.len() == 1 && !trailing_comma {
                    Ok(items.into_iter().next().unwrap_or(Value::None))
                } else {
                    Ok(Value::Tuple(items))
                }
            }
            Some('[') => self.sequence(']').map(|(items, _)| Value::List(items)),
            Some('\'') | Some('"') => self.string().map(Value::Str),
            Some(c) if c.is_ascii_digit() || c == '-' || c == '+' => self.integer(),
            Some(c) if c.is_ascii_alphabetic() => self.word(),
            _ => Err(self.unexpected("a value")),
        }
    }

    fn sequence(&mut self, close: char) -> Parsed<(Vec<Value>, bool)> {
        let mut trailing = false;
        let items = self.nested_with(close, &mut trailing, |p| p.value())?;
        Ok((items, trailing))
    }

    fn nested<T>(
        &mut self,
        close: char,
        item: impl FnMut(&mut Self) -> Parsed<T>,
    ) -> Parsed<Vec<T>> {
        let mut trailing = false;
        self.nested_with(close, &mut trailing, item)
    }

    /// Items separated by commas between an opening bracket (the next character) and `close`;
    /// `trailing` tells whether the last item was followed by a comma.
    fn nested_with<T>(
        &mut self,
        close: char,
        trailing: &mut bool,
        mut item: impl FnMut(&mut Self) -> Parsed<T>,
    ) -> Parsed<Vec<T>> {
        self.depth += 1;
        if self.depth > MAX_NESTING {
            return Err(format!(
                "invalid .npy header: brackets nested more than {MAX_NESTING} deep"
            ));
        }
        self.chars.next();
        let mut items = Vec::new();
        loop {
            if self.peek() == Some(close) {
                self.chars.next();
                break;
            }
            items.push(item(self)?);
            *trailing = false;
            match self.peek() {
                Some(',') => {
                    self.chars.next();
                    *trailing = true;
                }
                Some(c) if c == close => {}
                _ => return Err(self.unexpected(&format!("',' or '{close}'"))),
            }
        }
        self.depth -= 1;
        Ok(items)
    }

    fn string(&mut self) -> Parsed<String> {
        let quote = self.chars.next().map(|(_, c)| c).unwrap_or('\'');
        let mut s = String::new();
        loop {
            match self.chars.next() {
                None => {
                    return Err(
                        "invalid .npy header: a string is not closed before the end".to_string()
                    )
                }
                Some((_, c)) if c == quote => return Ok(s),
                Some((_, '\\')) => match self.chars.next() {
                    Some((_, c)) => s.push(c),
                    None => {
                        return Err("invalid .npy header: a string is not closed before the end"
                            .to_string())
                    }
                },
                Some((_, c)) => s.push(c),
            }
        }
    }

    fn integer(&mut self) -> Parsed<Value> {
        let mut s = String::new();
        if let Some(&(_, c)) = self.chars.peek() {
            if c == '-' || c == '+' {
                s.push(c);
                self.chars.next();
            }
        }
        while let Some(&(_, c)) = self.chars.peek() {
            if c.is_ascii_digit() || c == '_' {
                s.push(c);
                self.chars.next();
            } else {
                break;
            }
        }
        // Python 2 wrote long integers with a trailing L.
        if let Some(&(_, 'L' | 'l')) = self.chars.peek() {
            self.chars.next();
        }
        if !s.chars().any(|c| c.is_ascii_digit()) {
            return Err(self.unexpected("an integer"));
        }
        Ok(Value::Int(s))
    }

    fn word(&mut self) -> Parsed<Value> {
        let start = self.position();
        while let Some(&(_, c)) = self.chars.peek() {
            if c.is_ascii_alphanumeric() || c == '_' {
                self.chars.next();
            } else {
                break;
            }
        }
        let word = &self.text[start..self.position()];
        match word {
            "True" => Ok(Value::Bool(true)),
            "False" => Ok(Value::Bool(false)),
            "None" => Ok(Value::None),
            other => Err(format!(
                "invalid .npy header: unexpected word \"{}\" at character {start}",
                escape_quoted(other)
            )),
        }
    }
}

/// Checks the keys and the types of their values.
fn interpret(value: Value, data_offset: u64) -> Parsed<RawHeader> {
    let Value::Dict(entries) = value else {
        return Err("invalid .npy header: not a dict".to_string());
    };
    let (mut descr, mut fortran, mut shape) = (None, None, None);
    for (key, v) in entries {
        let Value::Str(name) = key else {
            return Err(format!(
                "invalid .npy header: a key is {}, expected 'descr', 'fortran_order' or 'shape'",
                key.kind()
            ));
        };
        let slot = match name.as_str() {
            "descr" => &mut descr,
            "fortran_order" => &mut fortran,
            "shape" => &mut shape,
            other => {
                return Err(format!(
                    "invalid .npy header: unexpected key '{}' (the keys are 'descr', \
                     'fortran_order' and 'shape')",
                    escape_quoted(other)
                ))
            }
        };
        if slot.is_some() {
            return Err(format!("invalid .npy header: key '{name}' appears twice"));
        }
        *slot = Some(v);
    }
    let missing = |k: &str| format!("invalid .npy header: the key '{k}' is missing");
    let descr = descr.ok_or_else(|| missing("descr"))?;
    let fortran = fortran.ok_or_else(|| missing("fortran_order"))?;
    let shape = shape.ok_or_else(|| missing("shape"))?;
    let (descr, structured) = match descr {
        Value::Str(s) => (Some(s), String::new()),
        Value::List(fields) => (
            None,
            format!("structured dtype with {} fields", fields.len()),
        ),
        other => {
            return Err(format!(
                "invalid .npy header: 'descr' is {}, expected a string such as '<f8'",
                other.kind()
            ))
        }
    };
    let fortran_order = match fortran {
        Value::Bool(b) => b,
        other => {
            return Err(format!(
                "invalid .npy header: 'fortran_order' is {} ({}), expected True or False",
                other.kind(),
                other.quote()
            ))
        }
    };
    let dims = match shape {
        Value::Tuple(d) => d,
        other => {
            return Err(format!(
                "invalid .npy header: 'shape' is {} ({}), expected a tuple of integers such as \
                 (4, 5)",
                other.kind(),
                other.quote()
            ))
        }
    };
    let shape = dims
        .into_iter()
        .enumerate()
        .map(|(axis, d)| match d {
            Value::Int(text) => {
                let digits = text.replace('_', "");
                if digits.starts_with('-') {
                    return Err(format!(
                        "invalid .npy header: axis {axis} of 'shape' has the negative length {}",
                        escape_quoted(&text)
                    ));
                }
                digits
                    .trim_start_matches('+')
                    .parse::<usize>()
                    .map_err(|_| {
                        format!(
                            "invalid .npy header: axis {axis} of 'shape' has the length {}, \
                             more than this machine can address",
                            escape_quoted(&text)
                        )
                    })
            }
            other => Err(format!(
                "invalid .npy header: axis {axis} of 'shape' is {} ({}), expected an integer",
                other.kind(),
                other.quote()
            )),
        })
        .collect::<Parsed<Vec<usize>>>()?;
    Ok(RawHeader {
        descr,
        structured,
        fortran_order,
        shape,
        data_offset,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(text: &str) -> Vec<u8> {
        let mut v = b"\x93NUMPY\x01\x00".to_vec();
        v.extend_from_slice(&(text.len() as u16).to_le_bytes());
        v.extend_from_slice(text.as_bytes());
        v
    }

    fn parse(text: &str) -> Result<RawHeader, HeaderError> {
        read_header(&mut file(text).as_slice())
    }

    #[test]
    fn reads_numpy_headers() {
        let h = parse("{'descr': '<f8', 'fortran_order': False, 'shape': (3, 4), }     \n")
            .expect("valid");
        assert_eq!(h.descr.as_deref(), Some("<f8"));
        assert!(!h.fortran_order);
        assert_eq!(h.shape, vec![3, 4]);
        assert_eq!(h.data_offset, 10 + 65);
        let one = parse("{\"shape\": (7,), \"fortran_order\": True, \"descr\": \"|i1\"}").unwrap();
        assert_eq!(one.shape, vec![7]);
        assert!(one.fortran_order);
        assert_eq!(
            parse("{'descr':'<f4','fortran_order':False,'shape':()}")
                .unwrap()
                .shape,
            Vec::<usize>::new()
        );
        assert_eq!(
            parse("{'descr':'<f4','fortran_order':False,'shape':(2L, 3L)}")
                .unwrap()
                .shape,
            vec![2, 3]
        );
        let s = parse("{'descr':[('a','<f4'),('b','<i4')],'fortran_order':False,'shape':(2,)}")
            .unwrap();
        assert_eq!(s.descr, None);
        assert!(s.structured.contains("2 fields"));
    }

    #[test]
    fn refuses_malformed_headers_in_one_line() {
        for (text, needle) in [
            (
                "{'descr': '<f8', 'fortran_order': False}",
                "'shape' is missing",
            ),
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': [3]}",
                "expected a tuple",
            ),
            (
                "{'descr': '<f8', 'fortran_order': 0, 'shape': (3,)}",
                "expected True or False",
            ),
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': (-3,)}",
                "negative length",
            ),
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': (99999999999999999999999,)}",
                "more than this machine",
            ),
            (
                "{'descr': '<f8', 'fortran_order': False, 'shape': (3,), 'x': 1}",
                "unexpected key 'x'",
            ),
            (
                "{'descr': '<f8', 'descr': '<f8', 'fortran_order': False, 'shape': (3,)}",
                "appears twice",
            ),
            ("{'descr': '<f8'", "ends where"),
            ("{'descr': '<f8\x1b[31m", "not closed"),
            ("[1, 2]", "a dict"),
        ] {
            match parse(text) {
                Err(HeaderError::Invalid(msg)) => {
                    assert!(msg.contains(needle), "{text:?}: {msg}");
                    assert!(!msg.chars().any(char::is_control), "{msg:?}");
                }
                other => panic!("{text:?}: {other:?}"),
            }
        }
    }

    #[test]
    fn deep_nesting_is_refused_at_once() {
        for open in ["[", "(", "{'a':"] {
            let deep = open.repeat(10_000);
            let text = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {deep}");
            let started = std::time::Instant::now();
            match parse(&text) {
                Err(HeaderError::Invalid(msg)) => assert!(msg.contains("nested"), "{msg}"),
                other => panic!("{other:?}"),
            }
            // Generous: the verdict is linear in the length; this only catches a regression to
            // exponential time, which would take minutes.
            assert!(started.elapsed().as_secs() < 5);
        }
    }

    #[test]
    fn control_bytes_are_escaped() {
        let msg = match parse("{'descr': '<f8', 'fortran_order': False, 'shape': (3,)}\x00\x1b") {
            Err(HeaderError::Invalid(m)) => m,
            other => panic!("{other:?}"),
        };
        assert!(msg.contains("\\x00\\x1b"), "{msg}");
        assert_eq!(escape_all("a\u{202e}b\u{85}"), "a\\u{202e}b\\x85");
    }

    #[test]
    fn lengths_and_versions_are_bounded() {
        let mut v = b"\x93NUMPY\x02\x00".to_vec();
        v.extend_from_slice(&u32::MAX.to_le_bytes());
        match read_header(&mut v.as_slice()) {
            Err(HeaderError::Invalid(m)) => assert!(m.contains("more than the"), "{m}"),
            other => panic!("{other:?}"),
        }
        let v = b"\x93NUMPY\x09\x00\x00\x00".to_vec();
        assert!(matches!(
            read_header(&mut v.as_slice()),
            Err(HeaderError::Invalid(_))
        ));
        assert_eq!(
            read_header(&mut &b"\x93NUM"[..]),
            Err(HeaderError::Truncated)
        );
        assert_eq!(
            read_header(&mut &b"PK\x03\x04xxxxxx"[..]),
            Err(HeaderError::NotNpy)
        );
    }
}
