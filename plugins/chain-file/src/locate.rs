//! Where a value is in the file, for the checks that need the whole file (stage two).
//!
//! ron reports the position of its cursor with every error. To find the value at a path
//! (`joints[2].name`, `errors[4]`), the file is deserialized once more by a seed that walks the
//! path, skips everything else, and fails the moment it stands before the value: the error's
//! span ends where the value starts. This runs only when there is an error to report, and it
//! gives the same line and column numbers (1-based, in characters) as ron's own errors.

use std::fmt;

use serde::de::{self, DeserializeSeed, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};

/// One step of a path into the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// The value of a struct field.
    Field(&'static str),
    /// An element of a list (0-based).
    Index(usize),
}

/// A line and a column, 1-based.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Position {
    /// Line.
    pub line: usize,
    /// Column, in characters.
    pub column: usize,
}

/// The message of the error that marks the place; it never reaches a user.
const MARK: &str = "\u{0}ballbar-chain-file: here";

/// The start of the value at `path` (the whole file for an empty path), or `None` if the file
/// does not parse as far or has no such value.
pub fn locate(text: &str, path: &[Step]) -> Option<Position> {
    let result: Result<(), ron::error::SpannedError> =
        ron::Options::default().from_str_seed(text, Walk(path));
    match result {
        Err(e) if e.code == ron::Error::Message(MARK.to_string()) => {
            Some(Position { line: e.span.end.line.max(1), column: e.span.end.col.max(1) })
        }
        _ => None,
    }
}

/// Walks the remaining path.
struct Walk<'p>(&'p [Step]);

impl<'de> DeserializeSeed<'de> for Walk<'_> {
    type Value = ();

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        if self.0.is_empty() {
            // Stand before the value, without reading it.
            return Err(de::Error::custom(MARK));
        }
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Walk<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a value with the path {:?}", self.0)
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let Some((&Step::Field(name), rest)) = self.0.split_first() else {
            return Err(de::Error::custom("not a list"));
        };
        while let Some(key) = map.next_key::<String>()? {
            if key == name {
                return map.next_value_seed(Walk(rest));
            }
            map.next_value::<IgnoredAny>()?;
        }
        Err(de::Error::custom(format!("no field {name}")))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let Some((&Step::Index(k), rest)) = self.0.split_first() else {
            return Err(de::Error::custom("not a struct"));
        };
        for _ in 0..k {
            if seq.next_element::<IgnoredAny>()?.is_none() {
                return Err(de::Error::custom(format!("no element {k}")));
            }
        }
        seq.next_element_seed(Walk(rest))?;
        Err(de::Error::custom(format!("no element {k}")))
    }
}
