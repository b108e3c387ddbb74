//! The DeepMimic clips shipped with the project (`assets/motions/`, MIT licence beside them),
//! built into the binary so that `train --motion backflip` needs no files.

/// A clip built into the binary.
#[derive(Debug)]
pub struct BuiltInClip {
    /// The short name a command takes (`backflip`).
    pub name: &'static str,
    /// The file's name in `assets/motions/` (`humanoid3d_backflip.txt`).
    pub file_name: &'static str,
    /// The file's text, verbatim.
    pub text: &'static str,
}

impl BuiltInClip {
    /// How the clip is named in reports and errors.
    pub fn label(&self) -> String {
        format!("assets/motions/{} (built in)", self.file_name)
    }
}

/// A built-in clip from `assets/motions/humanoid3d_<name>.txt`.
macro_rules! built_in {
    ($name:literal) => {
        BuiltInClip {
            name: $name,
            file_name: concat!("humanoid3d_", $name, ".txt"),
            text: include_str!(concat!("../../assets/motions/humanoid3d_", $name, ".txt")),
        }
    };
}

/// Every clip in `assets/motions/`, by name.
pub const BUILT_IN_CLIPS: [BuiltInClip; 13] = [
    built_in!("backflip"),
    built_in!("cartwheel"),
    built_in!("crawl"),
    built_in!("dance_b"),
    built_in!("dance_spin"),
    built_in!("getup_facedown"),
    built_in!("getup_faceup"),
    built_in!("jog"),
    built_in!("punch"),
    built_in!("run"),
    built_in!("spinkick"),
    built_in!("stealthy_walk"),
    built_in!("walk"),
];

/// The built-in clip a motion argument names: its short name (`backflip`), its file name
/// (`humanoid3d_backflip.txt`) or that without `.txt`, as a name is looked up in a directory.
pub fn find_built_in(motion: &str) -> Option<&'static BuiltInClip> {
    BUILT_IN_CLIPS.iter().find(|clip| {
        clip.name == motion
            || clip.file_name == motion
            || clip.file_name.strip_suffix(".txt") == Some(motion)
    })
}

/// The names of the built-in clips, comma-separated (for messages).
pub fn built_in_names() -> String {
    BUILT_IN_CLIPS
        .iter()
        .map(|clip| clip.name)
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_in_clip_is_found_by_each_of_its_names() {
        for clip in &BUILT_IN_CLIPS {
            let base = clip.file_name.trim_end_matches(".txt");
            for name in [clip.name, clip.file_name, base] {
                let found = find_built_in(name).map(|c| c.name);
                assert_eq!(found, Some(clip.name), "{name}");
            }
            assert!(clip.text.contains("\"Frames\""), "{}", clip.name);
        }
        assert!(find_built_in("backflip.txt").is_none());
        assert!(find_built_in("humanoid3d_").is_none());
        assert!(find_built_in("").is_none());
    }
}
