//! The replay page: one self-contained HTML file that plays a [`Recording`] in the browser
//! with three.js (vendored in `assets/three/`, inlined), the character drawn from the MJCF's
//! geoms, the reference as a translucent ghost, and a per-frame tracking-error plot under the
//! view (docs/replay.md).
//!
//! The page needs no network: three.js, the script, the style and the recording are inlined,
//! and a Content-Security-Policy forbids every fetch but `blob:` scripts (how the page loads
//! three.js's ES modules without a bundler). `#frame=N`, `#episode=E` and `#selftest` in the
//! URL are for screenshots and the headless-browser test (`tests/viewer_page.rs`).

mod data;
mod index;
mod source;

use std::path::Path;

use thiserror::Error;

use crate::files::write_bytes_atomically;
use crate::motion::Character;
use crate::recording::Recording;

pub use data::{PageData, PageSourceSkeleton, page_data};
pub use index::{ClipPageRow, clip_page_name, index_html, save_index_page};
pub use source::SourceSkeleton;

/// three.js 0.185.1 from npm (assets/three/README.md).
pub const THREE_CORE: &str = include_str!("../../assets/three/three.core.min.js");
pub const THREE_MODULE: &str = include_str!("../../assets/three/three.module.min.js");
pub const THREE_LICENSE: &str = include_str!("../../assets/three/LICENSE");
/// The page around the data, its style and its script.
const TEMPLATE: &str = include_str!("page/template.html");
const STYLE: &str = include_str!("page/style.css");
const SCRIPT: &str = include_str!("page/viewer.js");

/// A page that cannot be written.
#[derive(Debug, Error)]
pub enum ViewerError {
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("cannot build the page: {0}")]
    Build(String),
}

/// Text that may sit inside a `<script>` element: `</script` or `<!--` in it would end or
/// change the element (the HTML parser reads script contents as raw text).
fn script_safe(name: &str, text: &str) -> Result<(), ViewerError> {
    let lower = text.to_ascii_lowercase();
    if lower.contains("</script") || lower.contains("<!--") {
        return Err(ViewerError::Build(format!(
            "{name} contains `</script` or `<!--` and cannot be inlined"
        )));
    }
    Ok(())
}

/// The page's control for the source skeleton: its checkbox (on) and a sideways shift.
const SOURCE_CONTROLS: &str = r#"
    <label title="the mocap file's skeleton, as retargeting scaled and placed it"><input id="source" type="checkbox" checked> source skeleton</label>
    <label title="shift the source skeleton sideways on the screen (m)">shift <input id="source-shift" type="range" min="-1.5" max="1.5" step="0.05" value="0" aria-label="source skeleton shift"></label>"#;

/// The HTML page of `recording` for `character`, titled `title`.
pub fn page_html(
    recording: &Recording,
    character: &Character,
    title: &str,
) -> Result<String, ViewerError> {
    page_html_with_source(recording, character, title, None)
}

/// [`page_html`], with the source skeleton of a mocap file imported on the fly drawn beside the
/// character (a checkbox in the controls shows and hides it, a slider shifts it sideways).
/// Without one the page is [`page_html`]'s: no source data and no source controls.
pub fn page_html_with_source(
    recording: &Recording,
    character: &Character,
    title: &str,
    source: Option<&SourceSkeleton>,
) -> Result<String, ViewerError> {
    let mut data = page_data(recording, character, title);
    if let Some(source) = source {
        let rows = recording.meta.total_frames();
        if source.positions.len() != rows * source.joints() * 3 {
            return Err(ViewerError::Build(format!(
                "the source skeleton has {} values, not {rows} rows of {} joints",
                source.positions.len(),
                source.joints()
            )));
        }
        data.source_skeleton = Some(PageSourceSkeleton::new(source));
    }
    // JSON allows `\u003c` for `<`: then no `</script` or `<!--` can appear in the element.
    let json = serde_json::to_string(&data)
        .map_err(|e| ViewerError::Build(e.to_string()))?
        .replace('<', "\\u003c");
    for (name, text) in [
        ("three.core.min.js", THREE_CORE),
        ("three.module.min.js", THREE_MODULE),
        ("viewer.js", SCRIPT),
    ] {
        script_safe(name, text)?;
    }
    let parts = [
        ("{{TITLE}}", html_escape(title)),
        ("{{STYLE}}", STYLE.to_string()),
        ("{{THREE_LICENSE}}", html_escape(THREE_LICENSE)),
        ("{{THREE_CORE}}", THREE_CORE.to_string()),
        ("{{THREE_MODULE}}", THREE_MODULE.to_string()),
        (
            "{{SOURCE_CONTROLS}}",
            source.map_or(String::new(), |_| SOURCE_CONTROLS.to_string()),
        ),
        ("{{DATA}}", json),
        ("{{SCRIPT}}", SCRIPT.to_string()),
    ];
    // One pass over the template, so that a placeholder-like text inside an inserted part
    // (three.js, the data) is never replaced itself.
    let mut html =
        String::with_capacity(TEMPLATE.len() + parts.iter().map(|(_, p)| p.len()).sum::<usize>());
    let mut rest = TEMPLATE;
    while let Some(start) = rest.find("{{") {
        html.push_str(&rest[..start]);
        let (key, value) = parts
            .iter()
            .find(|(key, _)| rest[start..].starts_with(key))
            .ok_or_else(|| ViewerError::Build(format!("unknown placeholder at {start}")))?;
        html.push_str(value);
        rest = &rest[start + key.len()..];
    }
    html.push_str(rest);
    Ok(html)
}

/// Writes the page to `path` atomically.
pub fn save_page(
    path: &Path,
    recording: &Recording,
    character: &Character,
    title: &str,
) -> Result<usize, ViewerError> {
    save_page_with_source(path, recording, character, title, None)
}

/// [`save_page`] of [`page_html_with_source`].
pub fn save_page_with_source(
    path: &Path,
    recording: &Recording,
    character: &Character,
    title: &str,
    source: Option<&SourceSkeleton>,
) -> Result<usize, ViewerError> {
    let html = page_html_with_source(recording, character, title, source)?;
    write_bytes_atomically(path, html.as_bytes()).map_err(|error| ViewerError::Io {
        path: path.display().to_string(),
        error,
    })?;
    Ok(html.len())
}

fn html_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests;
