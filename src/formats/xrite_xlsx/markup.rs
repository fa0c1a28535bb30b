//! The tag scanner of the budget checks: the tags of a markup part in document order and
//! their attributes, read without building a document (so a part's size, not its shape,
//! bounds the work), and the numbers and `A1` references they hold.

/// One tag of an XML part, as the budget checks scan it (without building a document):
/// its local name, whether it closes an element, its attributes' text and its byte span.
pub(super) struct Tag<'a> {
    pub(super) local: &'a [u8],
    pub(super) closing: bool,
    pub(super) attrs: &'a [u8],
    pub(super) start: usize,
    pub(super) end: usize,
}

impl<'a> Tag<'a> {
    /// The value of the attribute named `key` (without a prefix), if the tag has it.
    pub(super) fn attribute(&self, key: &[u8]) -> Option<&'a [u8]> {
        let a = self.attrs;
        let mut i = 0;
        while i < a.len() {
            while i < a.len() && (a[i].is_ascii_whitespace() || a[i] == b'/') {
                i += 1;
            }
            let name_start = i;
            while i < a.len() && a[i] != b'=' && !a[i].is_ascii_whitespace() {
                i += 1;
            }
            let name = &a[name_start..i];
            while i < a.len() && (a[i].is_ascii_whitespace() || a[i] == b'=') {
                i += 1;
            }
            let quote = *a.get(i)?;
            if quote != b'"' && quote != b'\'' {
                return None;
            }
            let value_start = i + 1;
            let len = a[value_start..].iter().position(|&b| b == quote)?;
            i = value_start + len + 1;
            if name == key {
                return Some(&a[value_start..value_start + len]);
            }
        }
        None
    }
}

/// The tags of `xml` in document order (comments, CDATA, declarations and processing
/// instructions skipped).
pub(super) fn tags(xml: &[u8]) -> impl Iterator<Item = Tag<'_>> {
    let mut at = 0;
    std::iter::from_fn(move || {
        loop {
            let lt = at + xml.get(at..)?.iter().position(|&b| b == b'<')?;
            let rest = &xml[lt + 1..];
            if rest.starts_with(b"![CDATA[") || rest.starts_with(b"!--") {
                let close: &[u8] = if rest[1] == b'[' { b"]]>" } else { b"-->" };
                at = find(&xml[lt..], close).map_or(xml.len(), |i| lt + i + close.len());
                continue;
            }
            let gt = lt + xml[lt..].iter().position(|&b| b == b'>')?;
            at = gt + 1;
            let inner = &xml[lt + 1..gt];
            if matches!(inner.first(), Some(b'?' | b'!')) {
                continue;
            }
            let closing = inner.first() == Some(&b'/');
            let body = if closing { &inner[1..] } else { inner };
            let name_end = body
                .iter()
                .position(|b| b.is_ascii_whitespace() || *b == b'/')
                .unwrap_or(body.len());
            let name = &body[..name_end];
            let local = name.rsplit(|&b| b == b':').next().unwrap_or(name);
            return Some(Tag {
                local,
                closing,
                attrs: &body[name_end..],
                start: lt,
                end: gt + 1,
            });
        }
    })
}

pub(super) fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// A decimal number; `None` when it is not one (an overflow saturates).
pub(super) fn parse_u64(text: &[u8]) -> Option<u64> {
    let t = text.trim_ascii();
    if t.is_empty() || !t.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(t.iter().fold(0u64, |n, d| {
        n.saturating_mul(10).saturating_add(u64::from(d - b'0'))
    }))
}

/// An `A1`-style reference as 1-based (row, column): `None` for the row when it has no
/// digits; `None` when it is no reference.
pub(super) fn parse_reference(text: &[u8]) -> Option<(Option<u64>, u64)> {
    let t = text.trim_ascii();
    let t = t.strip_prefix(b"$").unwrap_or(t);
    let letters = t.iter().take_while(|b| b.is_ascii_alphabetic()).count();
    if letters == 0 {
        return None;
    }
    let col = t[..letters].iter().fold(0u64, |n, b| {
        n.saturating_mul(26)
            .saturating_add(u64::from(b.to_ascii_uppercase() - b'A' + 1))
    });
    let digits = &t[letters..];
    let digits = digits.strip_prefix(b"$").unwrap_or(digits);
    let row = if digits.is_empty() {
        None
    } else {
        Some(parse_u64(digits)?)
    };
    Some((row, col))
}
