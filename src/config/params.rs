//! Typed stage settings with documented parameters.
//!
//! Every stage's settings struct derives serde (`deny_unknown_fields`,
//! `default`) and lists its parameters in [`StageSettings::PARAMS`] with unit,
//! allowed range and meaning. Defaults come from `Default`, so the table
//! printed by `surfsynth stages` never drifts from the code, and ranges are
//! checked generically from the same table.

use serde::{Serialize, de::DeserializeOwned};

/// The allowed values of one parameter.
#[derive(Clone, Copy, Debug)]
pub enum ParamRange {
    /// Integer (or every integer of a list) in `min..=max`.
    Int(i64, i64),
    /// Odd integer (or list of them) in `min..=max`.
    OddInt(i64, i64),
    /// Float (or every float of a list) in `min..=max`.
    Float(f64, f64),
    /// A string out of a fixed set.
    OneOf(&'static [&'static str]),
    /// Anything of the right type; the text says what is meaningful.
    Any(&'static str),
}

impl std::fmt::Display for ParamRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ParamRange::Int(a, b) => write!(f, "{a}..={b}"),
            ParamRange::OddInt(a, b) => write!(f, "odd, {a}..={b}"),
            ParamRange::Float(a, b) => write!(f, "{a}..={b}"),
            ParamRange::OneOf(v) => write!(f, "{}", v.join(" | ")),
            ParamRange::Any(s) => write!(f, "{s}"),
        }
    }
}

/// Documentation of one parameter.
#[derive(Clone, Copy, Debug)]
pub struct ParamDoc {
    /// The TOML key.
    pub name: &'static str,
    /// Unit of the value (`"texels"`, `"world units"`, `"radians"`, `""`).
    pub unit: &'static str,
    /// Allowed values, checked on load.
    pub range: ParamRange,
    /// What it does, one sentence.
    pub doc: &'static str,
}

/// Settings of one stage: serde-loadable, documented, range-checked.
pub trait StageSettings:
    Serialize + DeserializeOwned + Default + Clone + Send + Sync + 'static
{
    /// One entry per TOML key, in the order `surfsynth stages` shows them.
    const PARAMS: &'static [ParamDoc];

    /// Checks across parameters that a per-parameter range cannot express.
    /// Returns `(parameter, message)`.
    fn check(&self) -> Result<(), (String, String)> {
        Ok(())
    }
}

/// Checks `value` against `range`, recursing into arrays.
pub fn check_range(value: &toml::Value, range: &ParamRange) -> Result<(), String> {
    match (value, range) {
        (toml::Value::Array(items), _) => items.iter().try_for_each(|v| check_range(v, range)),
        (toml::Value::Integer(i), ParamRange::Int(lo, hi)) => {
            if (*lo..=*hi).contains(i) {
                Ok(())
            } else {
                Err(format!("{i} is out of range; allowed: {range}"))
            }
        }
        (toml::Value::Integer(i), ParamRange::OddInt(lo, hi)) => {
            if (*lo..=*hi).contains(i) && i % 2 == 1 {
                Ok(())
            } else {
                Err(format!("{i} is not allowed; allowed: {range}"))
            }
        }
        (toml::Value::Float(x), ParamRange::Float(lo, hi)) => {
            if x.is_finite() && *lo <= *x && *x <= *hi {
                Ok(())
            } else {
                Err(format!("{x} is out of range; allowed: {range}"))
            }
        }
        (toml::Value::Integer(i), ParamRange::Float(lo, hi)) => {
            let x = *i as f64;
            if *lo <= x && x <= *hi {
                Ok(())
            } else {
                Err(format!("{x} is out of range; allowed: {range}"))
            }
        }
        (toml::Value::String(s), ParamRange::OneOf(allowed)) => {
            if allowed.contains(&s.as_str()) {
                Ok(())
            } else {
                Err(format!("{s:?} is not allowed; allowed: {range}"))
            }
        }
        _ => Ok(()),
    }
}

/// The default value of every parameter, as TOML.
pub fn defaults_table<S: StageSettings>() -> toml::Table {
    to_table(&S::default())
}

/// `value` as a TOML table whose floats are written shortest: an `f32` field
/// holding 0.2 becomes `0.2`, not the `0.20000000298023224` of its widening
/// to `f64`. `toml::Table::try_from` widens every `f32`; the TOML writer
/// prints an `f32` with its own shortest form, and re-reading that text
/// keeps it, so the table comes from the written text. Re-parsing the text
/// gives the same `f32` back.
pub fn to_table<T: Serialize>(value: &T) -> toml::Table {
    toml::to_string(value)
        .ok()
        .and_then(|text| toml::from_str(&text).ok())
        .or_else(|| toml::Table::try_from(value).ok())
        .unwrap_or_default()
}

/// `value` as JSON whose floats are written shortest, the same text round
/// trip as [`to_table`]: `serde_json::to_value` widens an `f32` (0.2 becomes
/// `0.20000000298023224`), while serde_json's writer prints an `f32` with
/// its own shortest form, which reads back as the nearest `f64`. Used for
/// everything `metrics.json` holds.
pub fn to_json<T: Serialize + ?Sized>(value: &T) -> serde_json::Value {
    serde_json::to_string(value)
        .ok()
        .and_then(|text| serde_json::from_str(&text).ok())
        .unwrap_or(serde_json::Value::Null)
}

/// Renders a TOML value compactly for tables and messages.
pub fn value_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => format!("{s:?}"),
        toml::Value::Float(f) => {
            let s = format!("{f}");
            if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
                s
            } else {
                format!("{s}.0")
            }
        }
        toml::Value::Array(a) => format!(
            "[{}]",
            a.iter().map(value_text).collect::<Vec<_>>().join(", ")
        ),
        other => other.to_string(),
    }
}
