//! The plan stage's reply: a Markdown strategy with the paper's six headings. A reply without
//! them is rejected with the missing headings named; the loop retries, then keeps the previous
//! strategy.

/// The headings a strategy must have, in the order the plan prompt asks for them.
pub const HEADINGS: [&str; 6] = [
    "# Current Strategy",
    "## Best Baseline",
    "## What Seems Promising",
    "## What To Avoid",
    "## Next Experiment",
    "## Wildcards",
];

/// Checks a plan reply and returns the strategy: from the `# Current Strategy` line on, with a
/// surrounding ```markdown fence and any preamble removed.
pub fn parse_strategy(reply: &str) -> Result<String, String> {
    let text = unfence(reply.trim());
    if text.is_empty() {
        return Err("the reply is empty; return the strategy as Markdown".to_string());
    }
    let lines: Vec<&str> = text.lines().collect();
    let mut missing = Vec::new();
    let mut repeated = Vec::new();
    let mut start = None;
    for heading in HEADINGS {
        let hits: Vec<usize> = lines
            .iter()
            .enumerate()
            .filter(|(_, line)| is_heading(line, heading))
            .map(|(i, _)| i)
            .collect();
        match hits.as_slice() {
            [] => missing.push(heading),
            [i] => {
                if heading == HEADINGS[0] {
                    start = Some(*i);
                }
            }
            _ => repeated.push(heading),
        }
    }
    if !missing.is_empty() || !repeated.is_empty() {
        let mut problem =
            String::from("the strategy must have each of these headings exactly once: ");
        problem.push_str(&HEADINGS.join(" | "));
        if !missing.is_empty() {
            problem.push_str(&format!("; missing: {}", missing.join(" | ")));
        }
        if !repeated.is_empty() {
            problem.push_str(&format!("; repeated: {}", repeated.join(" | ")));
        }
        return Err(problem);
    }
    // From the first heading to the end, or to the fence that closes a block holding it.
    let from = start.unwrap_or(0);
    let body: Vec<&str> = lines
        .get(from..)
        .unwrap_or_default()
        .iter()
        .take_while(|line| !line.trim_start().starts_with("```"))
        .copied()
        .collect();
    let kept = body.join("\n");
    if let Some(lost) = HEADINGS
        .iter()
        .find(|h| !kept.lines().any(|l| is_heading(l, h)))
    {
        return Err(format!(
            "the heading {lost} must follow # Current Strategy inside the same block"
        ));
    }
    Ok(kept.trim_end().to_string() + "\n")
}

/// The text under one heading (up to the next heading of any level).
pub fn section<'a>(strategy: &'a str, heading: &str) -> Option<String> {
    let mut lines = strategy
        .lines()
        .skip_while(|line| !is_heading(line, heading));
    lines.next()?;
    let body: Vec<&'a str> = lines
        .take_while(|line| !line.trim_start().starts_with('#'))
        .collect();
    Some(body.join("\n").trim().to_string())
}

/// `line` is `heading`, ignoring case and surrounding spaces.
fn is_heading(line: &str, heading: &str) -> bool {
    let line = line.trim();
    let (hashes, title) = heading.split_at(heading.find(' ').unwrap_or(0));
    line.strip_prefix(hashes)
        .filter(|rest| rest.starts_with(' '))
        .is_some_and(|rest| rest.trim().eq_ignore_ascii_case(title.trim()))
}

/// The body of a reply that is one fenced block; the text unchanged otherwise.
fn unfence(text: &str) -> &str {
    let Some(rest) = text.strip_prefix("```") else {
        return text;
    };
    let Some(body) = rest.find('\n').and_then(|i| rest.get(i + 1..)) else {
        return text;
    };
    body.trim_end().strip_suffix("```").map_or(text, str::trim)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strategy() -> String {
        HEADINGS
            .iter()
            .map(|h| format!("{h}\ntext under {h}\n"))
            .collect::<Vec<_>>()
            .join("\n")
    }

    #[test]
    fn a_complete_strategy_is_kept_from_its_first_heading() {
        let reply = format!("Sure, here it is:\n```markdown\n{}```", strategy());
        // A preamble before a fence: the fence is not the whole reply, the text is used as is.
        let parsed = parse_strategy(&reply).unwrap();
        assert!(parsed.starts_with("# Current Strategy"));
        let fenced = format!("```markdown\n{}```", strategy());
        assert!(
            parse_strategy(&fenced)
                .unwrap()
                .starts_with("# Current Strategy")
        );
        assert_eq!(
            section(&parsed, "## Next Experiment").as_deref(),
            Some("text under ## Next Experiment")
        );
    }

    #[test]
    fn missing_and_repeated_headings_are_named() {
        let err = parse_strategy("# Current Strategy\n## Wildcards\n## Wildcards\n").unwrap_err();
        assert!(err.contains("missing: ## Best Baseline"), "{err}");
        assert!(err.contains("repeated: ## Wildcards"), "{err}");
        assert!(parse_strategy("   ").is_err());
        // `###` is not `##`.
        let wrong_level = strategy().replace("## Wildcards", "### Wildcards");
        assert!(parse_strategy(&wrong_level).is_err());
    }
}
