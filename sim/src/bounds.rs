//! Allowed ranges of the numbers read from TOML files: the scenarios here,
//! and drogue-vision's config (which uses this module too).
//!
//! Each kind of file has one table, dotted key -> [`Range`]. [`check`] walks
//! every number of a parsed file (arrays element by element) and refuses a
//! number outside its key's range, or a number whose key has no range at all:
//! so a key added without a range fails its file's tests, never reaches a
//! user unchecked. NaN and infinities are outside every range.

use std::fmt;
use toml::Value;

/// A closed or half-open interval, optionally with 0 allowed besides it
/// ("0: off").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
    /// `lo` itself is excluded.
    pub lo_open: bool,
    /// `hi` itself is excluded.
    pub hi_open: bool,
    /// 0 is allowed as well (the key's "off" value).
    pub zero: bool,
}

impl Range {
    /// `lo <= x <= hi`.
    pub const fn closed(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            hi,
            lo_open: false,
            hi_open: false,
            zero: false,
        }
    }
    /// `lo < x <= hi`.
    pub const fn above(lo: f64, hi: f64) -> Self {
        Self {
            lo_open: true,
            ..Self::closed(lo, hi)
        }
    }
    /// `lo < x < hi`.
    pub const fn open(lo: f64, hi: f64) -> Self {
        Self {
            lo_open: true,
            hi_open: true,
            ..Self::closed(lo, hi)
        }
    }
    /// This range, or exactly 0.
    pub const fn or_zero(self) -> Self {
        Self { zero: true, ..self }
    }

    /// Whether `x` is allowed (never for NaN or an infinity).
    pub fn contains(&self, x: f64) -> bool {
        if !x.is_finite() {
            return false;
        }
        if self.zero && x == 0.0 {
            return true;
        }
        let above_lo = if self.lo_open {
            x > self.lo
        } else {
            x >= self.lo
        };
        let below_hi = if self.hi_open {
            x < self.hi
        } else {
            x <= self.hi
        };
        above_lo && below_hi
    }
}

impl fmt::Display for Range {
    /// `[0.1, 1000]`, `(0, 1)`, `0 or [0.1, 1000]`: the form written next to
    /// each key in the documented files.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.zero {
            write!(f, "0 or ")?;
        }
        let open = if self.lo_open { '(' } else { '[' };
        let close = if self.hi_open { ')' } else { ']' };
        write!(f, "{open}{}, {}{close}", num(self.lo), num(self.hi))
    }
}

/// A bound as written in the docs: whole numbers without a fraction.
fn num(x: f64) -> String {
    if x >= i64::MAX as f64 {
        i64::MAX.to_string()
    } else if x.fract() == 0.0 && x.abs() < 1e16 {
        format!("{}", x as i64)
    } else {
        format!("{x}")
    }
}

/// A number outside its range, or one with no range.
#[derive(Clone, Debug, PartialEq)]
pub struct Violation {
    /// Dotted key, e.g. `link.max_rate_hz`.
    pub key: String,
    /// The value as written (TOML form).
    pub value: String,
    /// `None`: the key has no range (a defect of the table).
    pub range: Option<Range>,
}

impl Violation {
    /// `[link] max_rate_hz` for a dotted key, the bare key at the top level.
    pub fn key_display(&self) -> String {
        match self.key.rsplit_once('.') {
            Some((section, key)) => format!("[{section}] {key}"),
            None => self.key.clone(),
        }
    }
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.range {
            Some(r) => write!(
                f,
                "{} = {} is outside the allowed range {r}",
                self.key_display(),
                self.value
            ),
            None => write!(
                f,
                "{} = {}: no allowed range is known for this key",
                self.key_display(),
                self.value
            ),
        }
    }
}

/// Looks a dotted key up in a table.
pub fn range_of(table: &[(&str, Range)], key: &str) -> Option<Range> {
    table.iter().find(|(k, _)| *k == key).map(|(_, r)| *r)
}

/// Checks every number of `value` (a parsed TOML document) against `table`;
/// the first violation in document order.
pub fn check(value: &Value, table: &[(&str, Range)]) -> Result<(), Violation> {
    let mut found = None;
    walk_numbers(value, "", &mut |key, v| {
        if found.is_some() {
            return;
        }
        let x = match v {
            Value::Integer(i) => *i as f64,
            Value::Float(x) => *x,
            _ => return,
        };
        let range = range_of(table, key);
        if !range.is_some_and(|r| r.contains(x)) {
            found = Some(Violation {
                key: key.to_string(),
                value: v.to_string(),
                range,
            });
        }
    });
    found.map_or(Ok(()), Err)
}

/// Calls `f(dotted_key, number)` for every integer and float of `value`,
/// array elements under their array's key.
pub fn walk_numbers(value: &Value, prefix: &str, f: &mut dyn FnMut(&str, &Value)) {
    match value {
        Value::Table(t) => {
            for (k, v) in t {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                walk_numbers(v, &key, f);
            }
        }
        Value::Array(a) => {
            for v in a {
                walk_numbers(v, prefix, f);
            }
        }
        Value::Integer(_) | Value::Float(_) => f(prefix, value),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_include_and_exclude_their_ends() {
        let r = Range::above(0.0, 1.0);
        assert!(!r.contains(0.0) && r.contains(1.0) && r.contains(1e-9));
        let r = Range::open(0.0, 1.0);
        assert!(!r.contains(1.0) && r.contains(0.5));
        let r = Range::closed(0.1, 1000.0).or_zero();
        assert!(r.contains(0.0) && !r.contains(1e-300) && r.contains(0.1));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(!Range::closed(-1e308, 1e308).or_zero().contains(bad));
        }
        assert_eq!(r.to_string(), "0 or [0.1, 1000]");
        assert_eq!(Range::open(0.0, 1.0).to_string(), "(0, 1)");
    }

    #[test]
    fn check_names_the_key_and_the_range() {
        let table = [
            ("a.x", Range::closed(0.0, 1.0)),
            ("a.v", Range::closed(0.0, 2.0)),
        ];
        let v: Value = toml::from_str("[a]\nx = 0.5\nv = [1.0, 3.0]\n").unwrap();
        let e = check(&v, &table).unwrap_err();
        assert_eq!(
            e.to_string(),
            "[a] v = 3.0 is outside the allowed range [0, 2]"
        );
        let v: Value = toml::from_str("[a]\nx = nan\n").unwrap();
        assert_eq!(check(&v, &table).unwrap_err().key, "a.x");
        let v: Value = toml::from_str("[a]\ny = 1\n").unwrap();
        assert_eq!(check(&v, &table).unwrap_err().range, None);
    }
}
