//! Lines and whitespace-separated tokens of the text formats (ASCII PLY, OFF, ASCII STL), with
//! the 1-based line number of each for error messages. Bytes, not `str`: a stray binary or
//! non-UTF-8 byte ends up inside a token, whose parse then fails naming its line.

/// The lines of `bytes`, ending in `\n`, `\r\n` or a lone `\r`; `first_line` is the number of
/// the first one (a PLY body starts after its header).
pub(super) struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Lines<'a> {
    pub(super) fn new(bytes: &'a [u8], first_line: usize) -> Lines<'a> {
        Lines {
            bytes,
            pos: 0,
            line: first_line,
        }
    }

    /// Bytes not yet returned.
    pub(super) fn rest(&self) -> usize {
        self.bytes.len() - self.pos
    }

    /// The line number of the next line (the last one's + 1 at the end).
    pub(super) fn line(&self) -> usize {
        self.line
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = (usize, &'a [u8]);

    fn next(&mut self) -> Option<(usize, &'a [u8])> {
        if self.pos >= self.bytes.len() {
            return None;
        }
        let rest = &self.bytes[self.pos..];
        let (len, eol) = match rest.iter().position(|&b| b == b'\n' || b == b'\r') {
            Some(i) if rest[i] == b'\r' && rest.get(i + 1) == Some(&b'\n') => (i, 2),
            Some(i) => (i, 1),
            None => (rest.len(), 0),
        };
        let number = self.line;
        self.pos += len + eol;
        self.line += 1;
        Some((number, &rest[..len]))
    }
}

/// The whitespace-separated tokens of a line.
pub(super) fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// `line` without a `#` comment.
pub(super) fn uncommented(line: &[u8]) -> &[u8] {
    match line.iter().position(|&b| b == b'#') {
        Some(i) => &line[..i],
        None => line,
    }
}

/// Tokens across lines, each with its line number; [`Tokens::skip_line`] drops the rest of
/// the current line (an STL solid's name).
pub(super) struct Tokens<'a> {
    lines: Lines<'a>,
    /// What is left of the current line.
    current: &'a [u8],
    current_line: usize,
}

impl<'a> Tokens<'a> {
    pub(super) fn new(bytes: &'a [u8], first_line: usize) -> Tokens<'a> {
        Tokens {
            lines: Lines::new(bytes, first_line),
            current: &[],
            current_line: first_line,
        }
    }

    /// The next token and its line, or `None` at the end of the text.
    pub(super) fn next_token(&mut self) -> Option<(usize, &'a [u8])> {
        loop {
            let start = self.current.iter().position(|b| !b.is_ascii_whitespace());
            if let Some(start) = start {
                let rest = &self.current[start..];
                let len = rest
                    .iter()
                    .position(|b| b.is_ascii_whitespace())
                    .unwrap_or(rest.len());
                self.current = &rest[len..];
                return Some((self.current_line, &rest[..len]));
            }
            let (n, line) = self.lines.next()?;
            self.current_line = n;
            self.current = line;
        }
    }

    pub(super) fn skip_line(&mut self) {
        self.current = &[];
    }

    /// The line of the last token returned (where "the file ends" errors point).
    pub(super) fn line(&self) -> usize {
        self.current_line
    }

    /// Bytes of the text not yet split into tokens.
    pub(super) fn rest(&self) -> usize {
        self.lines.rest()
    }
}

/// A token for an error message: lossy UTF-8, control characters escaped, at most 40 chars.
pub(super) fn shown(token: &[u8]) -> String {
    let s = String::from_utf8_lossy(token);
    let mut out: String = s.chars().take(40).collect();
    if s.chars().count() > 40 {
        out.push('…');
    }
    format!("{out:?}")
}

/// An `f64` from a decimal token (`nan`, `inf` and exponents as Rust reads them; non-finite
/// values are left to validation, as in OBJ).
pub(super) fn parse_f64(token: &[u8]) -> Option<f64> {
    std::str::from_utf8(token).ok()?.parse().ok()
}

/// An integer token; `Err(true)` when it is all digits but does not fit in 64 bits.
pub(super) fn parse_i64(token: &[u8]) -> Result<i64, bool> {
    let s = std::str::from_utf8(token).map_err(|_| false)?;
    s.parse::<i64>().map_err(|e| {
        matches!(
            e.kind(),
            std::num::IntErrorKind::PosOverflow | std::num::IntErrorKind::NegOverflow
        )
    })
}
