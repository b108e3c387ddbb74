//! JSON conventions of the files a run writes.

use serde::{Deserialize, Deserializer};

/// `null` read as NaN: serde_json writes non-finite floats as `null`.
pub fn nan_from_null<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}
