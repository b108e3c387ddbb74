//! Parse errors as a user reads them: one line, the line quoted, types in words. Every reader
//! of a TOML or JSON file a user writes (configurations, motion libraries, skeleton maps,
//! character descriptions) words its errors through these.

/// A TOML error as one line: "line 24, column 1 (`num_envz = 12`): unknown field `num_envz`,
/// expected one of ...", the line quoted (it names the key). toml's own text is a multi-line
/// snippet with a caret, which one line would squash.
pub fn toml_error_line(e: &toml::de::Error, text: &str) -> String {
    let message = plain_type_names(&e.message().trim().replace('\n', " "));
    let Some(before) = e.span().and_then(|span| text.get(..span.start)) else {
        return message;
    };
    let line = before.matches('\n').count() + 1;
    let start_of_line = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before[start_of_line..].chars().count() + 1;
    let quoted: String = text[start_of_line..]
        .lines()
        .next()
        .unwrap_or("")
        .trim()
        .chars()
        .take(60)
        .collect();
    format!("line {line}, column {column} (`{quoted}`): {message}")
}

/// serde's Rust type names in a message, in plain words: "expected u32" is "expected a whole
/// number from 0 to 4294967295", "expected f64" is "expected a number" (newcomer report
/// rows 34-35). Other words are left as they are.
pub fn plain_type_names(message: &str) -> String {
    const WORDS: [(&str, &str); 14] = [
        ("u8", "a whole number from 0 to 255"),
        ("u16", "a whole number from 0 to 65535"),
        ("u32", "a whole number from 0 to 4294967295"),
        ("u64", "a whole number ≥ 0"),
        ("usize", "a whole number ≥ 0"),
        ("i8", "a whole number"),
        ("i16", "a whole number"),
        ("i32", "a whole number"),
        ("i64", "a whole number"),
        ("isize", "a whole number"),
        ("f32", "a number"),
        ("f64", "a number"),
        ("a sequence", "a list"),
        ("a map", "a table"),
    ];
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(at) = rest.find("expected ") {
        let after = &rest[at + "expected ".len()..];
        out.push_str(&rest[..at + "expected ".len()]);
        let word = WORDS.iter().find(|(name, _)| {
            after.starts_with(name)
                && !after[name.len()..].starts_with(|c: char| c.is_ascii_alphanumeric() || c == '_')
        });
        rest = match word {
            Some((name, words)) => {
                out.push_str(words);
                &after[name.len()..]
            }
            None => after,
        };
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_type_names_change_only_whole_type_names() {
        assert_eq!(
            plain_type_names("expected u32, expected f64; expected usize"),
            "expected a whole number from 0 to 4294967295, expected a number; expected a whole number ≥ 0"
        );
        assert_eq!(plain_type_names("expected a sequence"), "expected a list");
        // Names that merely start like a type, and other words, stay.
        for kept in [
            "expected u32x",
            "expected f64_thing",
            "expected one of `num_envs`",
            "expected a string",
            "unexpected",
        ] {
            assert_eq!(plain_type_names(kept), kept);
        }
    }
}
