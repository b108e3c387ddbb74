//! The search space: the training-configuration parameters the agent may change, addressed by
//! dotted paths (`ppo.learning_rate`), each typed and bounded. A configuration tried by the
//! search is the base training configuration with every searchable parameter set from an
//! [`Assignment`]; nothing outside the search space is ever created or changed.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

/// One value of a searchable parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ParamValue {
    Bool(bool),
    Int(i64),
    Float(f64),
    Text(String),
}

impl ParamValue {
    /// The value as a number, for numeric parameters.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            ParamValue::Int(v) => Some(*v as f64),
            ParamValue::Float(v) => Some(*v),
            ParamValue::Bool(_) | ParamValue::Text(_) => None,
        }
    }

    /// The value as it goes into a TOML training configuration.
    pub fn to_toml(&self) -> toml::Value {
        match self {
            ParamValue::Bool(v) => toml::Value::Boolean(*v),
            ParamValue::Int(v) => toml::Value::Integer(*v),
            ParamValue::Float(v) => toml::Value::Float(*v),
            ParamValue::Text(v) => toml::Value::String(v.clone()),
        }
    }

    /// A scalar TOML value (a choice, or a value read from a configuration).
    pub fn from_toml(value: &toml::Value) -> Option<Self> {
        match value {
            toml::Value::Boolean(v) => Some(ParamValue::Bool(*v)),
            toml::Value::Integer(v) => Some(ParamValue::Int(*v)),
            toml::Value::Float(v) => Some(ParamValue::Float(*v)),
            toml::Value::String(v) => Some(ParamValue::Text(v.clone())),
            _ => None,
        }
    }

    /// The value as it appears in a proposal's JSON.
    pub fn to_json(&self) -> serde_json::Value {
        match self {
            ParamValue::Bool(v) => serde_json::Value::Bool(*v),
            ParamValue::Int(v) => serde_json::Value::from(*v),
            ParamValue::Float(v) => serde_json::Value::from(*v),
            ParamValue::Text(v) => serde_json::Value::String(v.clone()),
        }
    }
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamValue::Bool(v) => write!(f, "{v}"),
            ParamValue::Int(v) => write!(f, "{v}"),
            // `{:?}` keeps a decimal point (1.0, not 1), so a float reads as a float.
            ParamValue::Float(v) => write!(f, "{v:?}"),
            ParamValue::Text(v) => write!(f, "{v:?}"),
        }
    }
}

/// A numeric range, inclusive at both ends.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Range {
    pub lo: f64,
    pub hi: f64,
}

impl Range {
    pub fn contains(&self, v: f64) -> bool {
        self.lo <= v && v <= self.hi
    }
}

impl fmt::Display for Range {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{}, {}]", fmt_number(self.lo), fmt_number(self.hi))
    }
}

/// A number written the short way: 0.0005, 1e-06, 32.
pub fn fmt_number(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-4 || v.abs() >= 1e6) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// What values a parameter takes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ParamKind {
    /// A float or an integer within `bounds`; `widen_to` are the hard limits the bounds may
    /// grow to when a proposal asks for it (no widening when absent).
    Numeric {
        integer: bool,
        bounds: Range,
        log: bool,
        widen_to: Option<Range>,
    },
    Bool,
    /// One of a list of values.
    Choice {
        choices: Vec<ParamValue>,
    },
}

/// One searchable parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamSpec {
    /// Dotted path into the training configuration, e.g. `ppo.learning_rate`.
    pub name: String,
    pub kind: ParamKind,
    /// What the parameter does, for the agent.
    pub description: Option<String>,
}

impl ParamSpec {
    /// The type as the agent reads it: `float`, `int (log scale)`, `bool`, `choice`.
    pub fn type_name(&self) -> String {
        match &self.kind {
            ParamKind::Numeric { integer, log, .. } => {
                let base = if *integer { "int" } else { "float" };
                if *log {
                    format!("{base}, log scale")
                } else {
                    base.to_string()
                }
            }
            ParamKind::Bool => "bool".to_string(),
            ParamKind::Choice { .. } => "choice".to_string(),
        }
    }

    /// Brings a value read from a configuration to this parameter's type: an integer where a
    /// float is expected becomes a float. `None` when the type does not fit.
    pub fn coerce(&self, value: &ParamValue) -> Option<ParamValue> {
        match (&self.kind, value) {
            (ParamKind::Numeric { integer: false, .. }, ParamValue::Float(v)) => {
                Some(ParamValue::Float(*v))
            }
            (ParamKind::Numeric { integer: false, .. }, ParamValue::Int(v)) => {
                Some(ParamValue::Float(*v as f64))
            }
            (ParamKind::Numeric { integer: true, .. }, ParamValue::Int(v)) => {
                Some(ParamValue::Int(*v))
            }
            (ParamKind::Bool, ParamValue::Bool(v)) => Some(ParamValue::Bool(*v)),
            (ParamKind::Choice { choices }, v) => choices.iter().find(|c| choice_eq(c, v)).cloned(),
            _ => None,
        }
    }
}

/// Choice values compare numerically across int and float (4 matches 4.0).
pub(crate) fn choice_eq(choice: &ParamValue, value: &ParamValue) -> bool {
    match (choice.as_f64(), value.as_f64()) {
        (Some(a), Some(b)) => a == b,
        _ => choice == value,
    }
}

/// The value of every searchable parameter, by name: one point of the search space.
pub type Assignment = BTreeMap<String, ParamValue>;

/// The searchable parameters, in the order the configuration lists them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchSpace {
    pub params: Vec<ParamSpec>,
}

impl SearchSpace {
    pub fn get(&self, name: &str) -> Option<&ParamSpec> {
        self.params.iter().find(|p| p.name == name)
    }

    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.params.iter().map(|p| p.name.as_str())
    }

    /// Grows a numeric parameter's bounds so they include `value` (within its hard limits,
    /// which the caller has checked). Returns the bounds before and after.
    pub fn widen(&mut self, name: &str, value: f64) -> Option<(Range, Range)> {
        let spec = self.params.iter_mut().find(|p| p.name == name)?;
        let ParamKind::Numeric { bounds, .. } = &mut spec.kind else {
            return None;
        };
        let before = *bounds;
        bounds.lo = bounds.lo.min(value);
        bounds.hi = bounds.hi.max(value);
        Some((before, *bounds))
    }

    /// Sets the bounds of a numeric parameter (restoring widened bounds on resume).
    pub fn set_bounds(&mut self, name: &str, range: Range) -> bool {
        match self.params.iter_mut().find(|p| p.name == name) {
            Some(ParamSpec {
                kind: ParamKind::Numeric { bounds, .. },
                ..
            }) => {
                *bounds = range;
                true
            }
            _ => false,
        }
    }
}

/// A dotted path did not lead to a value or a place for one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{path}`: {problem}")]
pub struct PathError {
    pub path: String,
    pub problem: String,
}

/// Checks a dotted path: non-empty segments of letters, digits, `_` and `-`.
pub fn check_path(path: &str) -> Result<(), PathError> {
    let bad = path.split('.').any(|segment| {
        segment.is_empty()
            || !segment
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    });
    if bad {
        return Err(PathError {
            path: path.to_string(),
            problem: "not a dotted path of table keys (letters, digits, `_`, `-`)".to_string(),
        });
    }
    Ok(())
}

/// The value at a dotted path, if every table on the way exists.
pub fn get_path<'a>(table: &'a toml::Table, path: &str) -> Option<&'a toml::Value> {
    let mut segments = path.split('.');
    let first = segments.next()?;
    let mut value = table.get(first)?;
    for segment in segments {
        value = value.as_table()?.get(segment)?;
    }
    Some(value)
}

/// Sets the value at a dotted path, creating the tables on the way that are missing. Fails
/// when something on the way is a value rather than a table.
pub fn set_path(table: &mut toml::Table, path: &str, value: toml::Value) -> Result<(), PathError> {
    let segments: Vec<&str> = path.split('.').collect();
    let Some((last, parents)) = segments.split_last() else {
        return Err(PathError {
            path: path.to_string(),
            problem: "empty path".to_string(),
        });
    };
    let mut current = table;
    for (depth, segment) in parents.iter().enumerate() {
        let entry = current
            .entry(segment.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        current = entry.as_table_mut().ok_or_else(|| PathError {
            path: path.to_string(),
            problem: format!("`{}` is a value, not a table", parents[..=depth].join(".")),
        })?;
    }
    current.insert(last.to_string(), value);
    Ok(())
}

/// The base configuration with every parameter of `assignment` set.
pub fn apply(base: &toml::Table, assignment: &Assignment) -> Result<toml::Table, PathError> {
    let mut config = base.clone();
    for (name, value) in assignment {
        set_path(&mut config, name, value.to_toml())?;
    }
    Ok(config)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_get_and_set_nested_values() {
        let mut table: toml::Table = toml::from_str("[ppo]\nclip = 0.2\n").unwrap();
        assert_eq!(
            get_path(&table, "ppo.clip").and_then(toml::Value::as_float),
            Some(0.2)
        );
        set_path(&mut table, "reward.pose_weight", toml::Value::Float(12.0)).unwrap();
        assert_eq!(
            get_path(&table, "reward.pose_weight").and_then(toml::Value::as_float),
            Some(12.0)
        );
        let err = set_path(&mut table, "ppo.clip.x", toml::Value::Integer(1)).unwrap_err();
        assert!(err.problem.contains("`ppo.clip` is a value"), "{err}");
        assert!(get_path(&table, "ppo.missing").is_none());
    }

    #[test]
    fn path_syntax_is_checked() {
        assert!(check_path("ppo.learning_rate").is_ok());
        assert!(check_path("ppo..lr").is_err());
        assert!(check_path("ppo.lr ").is_err());
        assert!(check_path("").is_err());
    }

    #[test]
    fn values_coerce_to_the_parameter_type() {
        let float = ParamSpec {
            name: "a".into(),
            kind: ParamKind::Numeric {
                integer: false,
                bounds: Range { lo: 0.0, hi: 1.0 },
                log: false,
                widen_to: None,
            },
            description: None,
        };
        assert_eq!(
            float.coerce(&ParamValue::Int(1)),
            Some(ParamValue::Float(1.0))
        );
        assert_eq!(float.coerce(&ParamValue::Bool(true)), None);
        let choice = ParamSpec {
            name: "c".into(),
            kind: ParamKind::Choice {
                choices: vec![ParamValue::Int(4), ParamValue::Text("x".into())],
            },
            description: None,
        };
        assert_eq!(
            choice.coerce(&ParamValue::Float(4.0)),
            Some(ParamValue::Int(4))
        );
        assert_eq!(choice.coerce(&ParamValue::Text("y".into())), None);
    }
}
