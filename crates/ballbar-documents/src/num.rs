//! Numbers as the documents hold them: JSON has no NaN or infinity, so a non-finite number is
//! written as `null` (serde_json's rule) and read back as NaN; a number a document leaves out
//! (one written by a version that did not have it) is read as NaN too: not known, never 0.

use std::collections::BTreeMap;

use serde::{Deserialize, Deserializer};

/// NaN: the value of a number the document leaves out.
pub(crate) fn nan() -> f64 {
    f64::NAN
}

/// A number, `null` read as NaN.
pub(crate) fn f64<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Two numbers (an interval, a sector): a shorter array is completed with NaN and `null` read
/// as NaN, so that a malformed entry reads as not finite rather than failing the document.
pub(crate) fn pair<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    let v = Vec::<Option<f64>>::deserialize(d)?;
    let at = |i: usize| v.get(i).copied().flatten().unwrap_or(f64::NAN);
    Ok([at(0), at(1)])
}

/// `[NaN, NaN]`: the value of a pair the document leaves out.
pub(crate) fn nan_pair() -> [f64; 2] {
    [f64::NAN; 2]
}

/// A map of names to numbers, `null` values read as NaN.
pub(crate) fn map<'de, D: Deserializer<'de>>(d: D) -> Result<BTreeMap<String, f64>, D::Error> {
    Ok(BTreeMap::<String, Option<f64>>::deserialize(d)?
        .into_iter()
        .map(|(k, v)| (k, v.unwrap_or(f64::NAN)))
        .collect())
}
