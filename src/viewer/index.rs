//! The index page of `replay --all-clips`: one row per clip of a library checkpoint's
//! evaluation, colored by its success rate as `clips.png` is, linking to the clip's replay page
//! in the same directory. Plain HTML, no script.

use std::fmt::Write as _;
use std::path::Path;

use super::{ViewerError, html_escape};
use crate::files::write_bytes_atomically;

/// One clip's row.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipPageRow {
    pub clip: String,
    /// The clip's page, relative to the index.
    pub page: String,
    pub duration_s: f64,
    pub episodes: u32,
    pub succeeded: u32,
    pub success_rate: f64,
    pub global_mpjpe_m: f64,
}

/// A success rate's background: red (0) through yellow to green (1), pale enough for text.
fn rate_color(rate: f64) -> String {
    if !rate.is_finite() {
        return "#eee".to_owned();
    }
    let hue = 120.0 * rate.clamp(0.0, 1.0);
    format!("hsl({hue:.0}, 70%, 85%)")
}

/// The index page: `title` as heading, `lines` (already plain text) under it, then the table.
pub fn index_html(title: &str, lines: &[String], rows: &[ClipPageRow]) -> String {
    let mut html = String::new();
    let title = html_escape(title);
    let _ = write!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; style-src 'unsafe-inline'\">\n\
         <title>{title}</title>\n<style>\n\
         body {{ font-family: system-ui, sans-serif; margin: 2em; }}\n\
         table {{ border-collapse: collapse; }}\n\
         th, td {{ padding: 0.3em 0.8em; text-align: right; border-bottom: 1px solid #ccc; }}\n\
         th:first-child, td:first-child {{ text-align: left; }}\n\
         </style>\n</head>\n<body>\n<h1>{title}</h1>\n"
    );
    for line in lines {
        let _ = writeln!(html, "<p>{}</p>", html_escape(line));
    }
    html.push_str(
        "<table>\n<tr><th>clip</th><th>duration</th><th>episodes</th><th>succeeded</th>\
         <th>success rate</th><th>global MPJPE</th></tr>\n",
    );
    for row in rows {
        let mpjpe = if row.global_mpjpe_m.is_finite() {
            format!("{:.3} m", row.global_mpjpe_m)
        } else {
            "-".to_owned()
        };
        let _ = writeln!(
            html,
            "<tr style=\"background: {}\"><td><a href=\"{}\">{}</a></td><td>{:.2} s</td><td>{}</td>\
             <td>{}</td><td>{:.3}</td><td>{}</td></tr>",
            rate_color(row.success_rate),
            html_escape(&row.page),
            html_escape(&row.clip),
            row.duration_s,
            row.episodes,
            row.succeeded,
            row.success_rate,
            mpjpe
        );
    }
    html.push_str("</table>\n</body>\n</html>\n");
    html
}

/// Writes [`index_html`] to `path` atomically; returns its size in bytes.
pub fn save_index_page(
    path: &Path,
    title: &str,
    lines: &[String],
    rows: &[ClipPageRow],
) -> Result<usize, ViewerError> {
    let html = index_html(title, lines, rows);
    write_bytes_atomically(path, html.as_bytes()).map_err(|error| ViewerError::Io {
        path: path.display().to_string(),
        error,
    })?;
    Ok(html.len())
}

/// A file name for a clip's page: its position (zero-padded to `width` digits, so that the
/// files sort as the library does and two clips never share one) and its name with every
/// character but ASCII letters, digits, `-` and `_` replaced by `_`.
pub fn clip_page_name(position: usize, width: usize, clip: &str) -> String {
    let safe: String = clip
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("{position:0width$}_{safe}.html")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(clip: &str, rate: f64) -> ClipPageRow {
        ClipPageRow {
            clip: clip.to_owned(),
            page: clip_page_name(3, 2, clip),
            duration_s: 1.75,
            episodes: 186,
            succeeded: (186.0 * rate) as u32,
            success_rate: rate,
            global_mpjpe_m: 0.0947,
        }
    }

    #[test]
    fn page_names_sort_as_the_library_and_keep_only_safe_characters() {
        assert_eq!(clip_page_name(3, 2, "backflip"), "03_backflip.html");
        assert_eq!(clip_page_name(12, 3, "a b/../c\"<"), "012_a_b____c__.html");
        assert_eq!(clip_page_name(0, 1, "long_walk1"), "0_long_walk1.html");
    }

    #[test]
    fn the_index_links_every_clip_escapes_names_and_colors_by_rate() {
        let rows = [row("backflip", 0.85), row("<b>&x", 0.0), row("walk", 1.0)];
        let html = index_html(
            "a <library>",
            &["22 clips".to_owned(), "success 0.964".to_owned()],
            &rows,
        );
        assert!(html.contains("<title>a &lt;library&gt;</title>"), "{html}");
        assert!(html.contains("<p>22 clips</p>"), "{html}");
        assert!(
            html.contains("<a href=\"03_backflip.html\">backflip</a>"),
            "{html}"
        );
        assert!(html.contains("&lt;b&gt;&amp;x</a>"), "{html}");
        assert!(!html.contains("<b>&x"), "{html}");
        assert!(html.contains("<td>0.850</td><td>0.095 m</td>"), "{html}");
        assert!(html.contains("hsl(0, 70%, 85%)"), "{html}");
        assert!(html.contains("hsl(120, 70%, 85%)"), "{html}");
        assert_eq!(html.matches("<tr style=").count(), 3);
        // No script may run: the page's policy allows inline style only.
        assert!(!html.contains("<script"), "{html}");
    }

    #[test]
    fn a_missing_mpjpe_is_a_dash() {
        let mut r = row("walk", 1.0);
        r.global_mpjpe_m = f64::NAN;
        assert!(index_html("t", &[], &[r]).contains("<td>-</td>"));
    }
}
