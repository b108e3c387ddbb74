//! The propose stage's reply: finding the JSON object in it and checking it against the search
//! space. The shape is the paper's:
//!
//! ```json
//! {"summary": "...",
//!  "search_base_selection": {"source": "cycle_012", "rationale": "..."},
//!  "params": [{"name": "ppo.learning_rate", "values": [0.0004, 0.0008]}]}
//! ```
//!
//! A reply that fails any check is rejected with every problem found; the problems go into the
//! next propose prompt as `validation_feedback`.

use std::fmt;

use crate::hpo::record::{CycleRecord, cycle_name};
use crate::hpo::space::{ParamKind, ParamSpec, ParamValue, Range, SearchSpace, choice_eq};

/// An accepted proposal.
#[derive(Debug, Clone, PartialEq)]
pub struct Proposal {
    pub summary: String,
    /// The cycle whose configuration the candidates change.
    pub base_cycle: u32,
    pub rationale: String,
    pub param: String,
    /// Candidate values, typed, in the order given, without repeats.
    pub values: Vec<ParamValue>,
    /// Bounds the parameter must widen to so that every value lies within them.
    pub widen_to: Option<Range>,
}

/// Why a reply was rejected: every problem found, each a sentence the agent can act on.
#[derive(Debug, Clone, PartialEq)]
pub struct ProposalError {
    pub problems: Vec<String>,
}

impl fmt::Display for ProposalError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.problems.join("; "))
    }
}

impl std::error::Error for ProposalError {}

impl ProposalError {
    fn one(problem: impl Into<String>) -> Self {
        ProposalError {
            problems: vec![problem.into()],
        }
    }
}

/// What a proposal is checked against.
pub struct ProposalRules<'a> {
    pub space: &'a SearchSpace,
    pub min_candidates: usize,
    pub max_candidates: usize,
    /// Every cycle so far (index = cycle number), for the search base.
    pub history: &'a [CycleRecord],
    pub incumbent_cycle: u32,
    pub best_cycle: u32,
}

/// Finds the JSON object in a reply and checks it.
pub fn parse_proposal(reply: &str, rules: &ProposalRules<'_>) -> Result<Proposal, ProposalError> {
    let json = extract_json_object(reply).map_err(ProposalError::one)?;
    validate(&json, rules)
}

/// The JSON object in a reply: the whole reply, a fenced code block, or the first balanced
/// `{...}` in prose. An object with a `params` key wins over other objects.
pub fn extract_json_object(reply: &str) -> Result<serde_json::Value, String> {
    let trimmed = reply.trim();
    if trimmed.is_empty() {
        return Err("the reply is empty; return one JSON object".to_string());
    }
    let mut candidates: Vec<&str> = vec![trimmed];
    candidates.extend(fenced_blocks(trimmed));
    candidates.extend(balanced_objects(trimmed));
    // An object cut short has no balanced end: parse from its `{` to report why.
    if let Some(start) = trimmed.find('{') {
        candidates.push(&trimmed[start..]);
    }
    let mut first_object = None;
    let mut first_error = None;
    for text in candidates {
        match serde_json::from_str::<serde_json::Value>(text) {
            Ok(value @ serde_json::Value::Object(_)) => {
                if value.get("params").is_some() {
                    return Ok(value);
                }
                first_object.get_or_insert(value);
            }
            Ok(_) => {}
            Err(e) => {
                if text.starts_with('{') {
                    first_error.get_or_insert(e.to_string());
                }
            }
        }
    }
    if let Some(value) = first_object {
        return Ok(value);
    }
    Err(match first_error {
        Some(e) => {
            format!("the reply's JSON object does not parse ({e}); return one valid JSON object")
        }
        None => "the reply holds no JSON object; return one JSON object".to_string(),
    })
}

/// The contents of ``` fenced blocks (the language tag line dropped).
fn fenced_blocks(text: &str) -> Vec<&str> {
    let mut blocks = Vec::new();
    let mut rest = text;
    while let Some(start) = rest.find("```") {
        let after = &rest[start + 3..];
        let body_start = after.find('\n').map_or(after.len(), |i| i + 1);
        let body = &after[body_start..];
        let Some(end) = body.find("```") else { break };
        blocks.push(body[..end].trim());
        rest = &body[end + 3..];
    }
    blocks
}

/// Substrings from a `{` to its matching `}`, skipping braces inside JSON strings. Bounded,
/// so a hostile reply full of braces costs little.
fn balanced_objects(text: &str) -> Vec<&str> {
    const MAX_STARTS: usize = 64;
    let bytes = text.as_bytes();
    let mut found = Vec::new();
    for (start, _) in text.match_indices('{').take(MAX_STARTS) {
        let mut depth = 0usize;
        let mut in_string = false;
        let mut escaped = false;
        for (offset, &b) in bytes[start..].iter().enumerate() {
            if in_string {
                match (escaped, b) {
                    (true, _) => escaped = false,
                    (false, b'\\') => escaped = true,
                    (false, b'"') => in_string = false,
                    _ => {}
                }
                continue;
            }
            match b {
                b'"' => in_string = true,
                b'{' => depth += 1,
                b'}' => {
                    depth -= 1;
                    if depth == 0 {
                        // `{` and `}` are ASCII, so both ends are char boundaries.
                        if let Some(object) = text.get(start..=start + offset) {
                            found.push(object);
                        }
                        break;
                    }
                }
                _ => {}
            }
        }
    }
    found
}

/// Shortens text the agent wrote before quoting it back.
fn quote(text: &str) -> String {
    const MAX: usize = 80;
    if text.chars().count() <= MAX {
        format!("{text:?}")
    } else {
        let cut: String = text.chars().take(MAX).collect();
        format!("{cut:?}...")
    }
}

fn validate(
    json: &serde_json::Value,
    rules: &ProposalRules<'_>,
) -> Result<Proposal, ProposalError> {
    let mut problems = Vec::new();
    let summary = match json.get("summary") {
        None | Some(serde_json::Value::Null) => String::new(),
        Some(serde_json::Value::String(s)) => s.clone(),
        Some(_) => {
            problems.push("`summary` must be a string".to_string());
            String::new()
        }
    };
    let (base_cycle, rationale) = match search_base(json, rules) {
        Ok(base) => base,
        Err(problem) => {
            problems.push(problem);
            (0, String::new())
        }
    };
    let param = match json.get("params") {
        Some(serde_json::Value::Array(params)) if params.len() == 1 => params.first(),
        Some(serde_json::Value::Array(params)) => {
            problems.push(format!(
                "`params` must list exactly one parameter (got {}); choose one axis per cycle",
                params.len()
            ));
            None
        }
        _ => {
            problems.push("`params` is missing or not a list; give `params: [{\"name\": ..., \"values\": [...]}]`".to_string());
            None
        }
    };
    let mut checked = None;
    if let Some(param) = param {
        match check_param(param, rules) {
            Ok(values) => checked = Some(values),
            Err(mut more) => problems.append(&mut more),
        }
    }
    match (checked, problems.is_empty()) {
        (Some((name, values, widen_to)), true) => Ok(Proposal {
            summary,
            base_cycle,
            rationale,
            param: name,
            values,
            widen_to,
        }),
        _ => Err(ProposalError { problems }),
    }
}

/// The search base: `cycle_XXX` of a cycle that produced a configuration (or `incumbent`,
/// `best`).
fn search_base(
    json: &serde_json::Value,
    rules: &ProposalRules<'_>,
) -> Result<(u32, String), String> {
    let selection = json.get("search_base_selection").ok_or(
        "`search_base_selection` is missing; give {\"source\": \"cycle_XXX\", \"rationale\": \"...\"}",
    )?;
    let source = selection
        .get("source")
        .and_then(serde_json::Value::as_str)
        .ok_or("`search_base_selection.source` must be a string such as \"cycle_003\"")?;
    let rationale = selection
        .get("rationale")
        .and_then(serde_json::Value::as_str)
        .unwrap_or_default()
        .to_string();
    let cycle = match source.trim() {
        "incumbent" => rules.incumbent_cycle,
        "best" => rules.best_cycle,
        s => s
            .strip_prefix("cycle_")
            .filter(|digits| !digits.is_empty() && digits.len() <= 9 && digits.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|digits| digits.parse::<u32>().ok())
            .ok_or_else(|| {
                format!(
                    "search base {} is not a cycle name; use \"cycle_XXX\" (cycle_000 is the baseline)",
                    quote(source)
                )
            })?,
    };
    match rules.history.get(cycle as usize) {
        Some(record) if record.assignment.is_some() => Ok((cycle, rationale)),
        Some(_) => Err(format!(
            "search base {} trained nothing (its proposal was rejected); choose a cycle that has results",
            cycle_name(cycle)
        )),
        None => Err(format!(
            "search base {} does not exist yet; the latest cycle is {}",
            cycle_name(cycle),
            cycle_name(rules.history.len().saturating_sub(1) as u32)
        )),
    }
}

type CheckedParam = (String, Vec<ParamValue>, Option<Range>);

fn check_param(
    param: &serde_json::Value,
    rules: &ProposalRules<'_>,
) -> Result<CheckedParam, Vec<String>> {
    let name = param
        .get("name")
        .and_then(serde_json::Value::as_str)
        .ok_or_else(|| vec!["`params[0].name` must be a string".to_string()])?;
    let Some(spec) = rules.space.get(name) else {
        let known: Vec<&str> = rules.space.names().collect();
        return Err(vec![format!(
            "unknown parameter {}; the searchable parameters are: {}",
            quote(name),
            known.join(", ")
        )]);
    };
    let raw_values = param
        .get("values")
        .and_then(serde_json::Value::as_array)
        .ok_or_else(|| {
            vec![format!(
                "`params[0].values` for `{name}` must be a list of values"
            )]
        })?;
    let limits = format!(
        "between {} and {} candidate values",
        rules.min_candidates, rules.max_candidates
    );
    if raw_values.len() > rules.max_candidates.saturating_mul(4).max(16) {
        return Err(vec![format!(
            "{} values for `{name}`; give {limits}",
            raw_values.len()
        )]);
    }
    let mut problems = Vec::new();
    let mut values: Vec<ParamValue> = Vec::new();
    let mut needed: Option<Range> = None;
    for (i, raw) in raw_values.iter().enumerate() {
        match check_value(spec, raw) {
            Ok((value, outside)) => {
                if let Some(x) = outside {
                    needed = Some(match needed {
                        None => Range { lo: x, hi: x },
                        Some(r) => Range {
                            lo: r.lo.min(x),
                            hi: r.hi.max(x),
                        },
                    });
                }
                if !values.iter().any(|v| choice_eq(v, &value)) {
                    values.push(value);
                }
            }
            Err(problem) => problems.push(format!("`{name}` value #{} ({raw}): {problem}", i + 1)),
        }
    }
    if problems.is_empty()
        && (values.len() < rules.min_candidates || values.len() > rules.max_candidates)
    {
        problems.push(format!(
            "{} distinct values for `{name}`; give {limits}",
            values.len()
        ));
    }
    if !problems.is_empty() {
        return Err(problems);
    }
    let widen_to = match (&spec.kind, needed) {
        (ParamKind::Numeric { bounds, .. }, Some(outside)) => Some(Range {
            lo: bounds.lo.min(outside.lo),
            hi: bounds.hi.max(outside.hi),
        }),
        _ => None,
    };
    Ok((name.to_string(), values, widen_to))
}

/// A value typed for the parameter, and the number when it lies outside the current bounds but
/// within the widening limits.
fn check_value(
    spec: &ParamSpec,
    raw: &serde_json::Value,
) -> Result<(ParamValue, Option<f64>), String> {
    match &spec.kind {
        ParamKind::Numeric {
            integer,
            bounds,
            log,
            widen_to,
        } => {
            let x = raw.as_f64().ok_or("not a number")?;
            let value = if *integer {
                if x.fract() != 0.0 || x.abs() > 9.0e15 {
                    return Err("not a whole number; this parameter is an int".to_string());
                }
                ParamValue::Int(x as i64)
            } else {
                ParamValue::Float(x)
            };
            if *log && x <= 0.0 {
                return Err("must be above 0 (log-scale parameter)".to_string());
            }
            if bounds.contains(x) {
                return Ok((value, None));
            }
            match widen_to {
                Some(hard) if hard.contains(x) => Ok((value, Some(x))),
                Some(hard) => Err(format!(
                    "outside the bounds {bounds} and beyond the widening limit {hard}"
                )),
                None => Err(format!(
                    "outside the bounds {bounds}, which this parameter cannot widen"
                )),
            }
        }
        ParamKind::Bool => raw
            .as_bool()
            .map(|b| (ParamValue::Bool(b), None))
            .ok_or_else(|| "must be true or false".to_string()),
        ParamKind::Choice { choices } => {
            let value = match raw {
                serde_json::Value::String(s) => Some(ParamValue::Text(s.clone())),
                serde_json::Value::Bool(b) => Some(ParamValue::Bool(*b)),
                serde_json::Value::Number(n) => n
                    .as_i64()
                    .map(ParamValue::Int)
                    .or_else(|| n.as_f64().map(ParamValue::Float)),
                _ => None,
            };
            value
                .and_then(|v| choices.iter().find(|c| choice_eq(c, &v)).cloned())
                .map(|c| (c, None))
                .ok_or_else(|| {
                    let list: Vec<String> = choices.iter().map(ToString::to_string).collect();
                    format!("not one of the choices {}", list.join(", "))
                })
        }
    }
}
