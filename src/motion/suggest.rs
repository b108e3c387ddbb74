//! "Did you mean": the known names nearest a mistyped one (a clip, a character), by edit
//! distance with transpositions (`wlak` is one edit from `walk`), case ignored.

/// The candidates nearest `name`: those at the smallest edit distance, if that distance is
/// small for the name's length (at most a third of it, and at least one edit), in the order
/// given and each once. Empty when nothing is close.
pub fn nearest<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let name = name.to_lowercase();
    let limit = (name.chars().count() / 3).max(1);
    let mut best: Vec<String> = Vec::new();
    let mut best_distance = limit + 1;
    for candidate in candidates {
        let distance = strsim::osa_distance(&name, &candidate.to_lowercase());
        if distance < best_distance {
            best_distance = distance;
            best.clear();
        }
        if distance == best_distance && !best.iter().any(|b| b == candidate) {
            best.push(candidate.to_string());
        }
    }
    best
}

/// ` (did you mean "walk"?)`, or ` (did you mean "a" or "b"?)`, for the candidates nearest
/// `name`; empty when none is close.
pub fn did_you_mean<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> String {
    let names: Vec<String> = nearest(name, candidates)
        .iter()
        .map(|n| format!("{n:?}"))
        .collect();
    match names.as_slice() {
        [] => String::new(),
        [one] => format!(" (did you mean {one}?)"),
        [rest @ .., last] => format!(" (did you mean {} or {last}?)", rest.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CLIPS: [&str; 5] = ["walk", "run", "spinkick", "backflip", "cartwheel"];

    #[test]
    fn a_typo_suggests_the_nearest_name() {
        assert_eq!(
            did_you_mean("bakflip", CLIPS),
            " (did you mean \"backflip\"?)"
        );
        assert_eq!(did_you_mean("wlak", CLIPS), " (did you mean \"walk\"?)");
        assert_eq!(
            did_you_mean("Cartweel", CLIPS),
            " (did you mean \"cartwheel\"?)"
        );
        assert_eq!(did_you_mean("rnu", CLIPS), " (did you mean \"run\"?)");
    }

    #[test]
    fn a_name_far_from_every_candidate_suggests_nothing() {
        assert_eq!(did_you_mean("nosuch", CLIPS), "");
        assert_eq!(did_you_mean("jump", CLIPS), "");
        assert_eq!(did_you_mean("", CLIPS), "");
    }

    #[test]
    fn ties_are_all_named_once() {
        assert_eq!(
            did_you_mean("g2", ["g1", "h2", "g1"]),
            " (did you mean \"g1\" or \"h2\"?)"
        );
    }
}
