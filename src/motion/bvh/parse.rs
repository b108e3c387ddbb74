//! The BVH text: the HIERARCHY (joints, their OFFSETs and CHANNELS, End Sites) and the MOTION
//! (`Frames:`, `Frame Time:`, one line of channel values per frame). Keywords and channel names
//! are read in any case, tokens may be separated by any whitespace (tabs, CRLF line ends). Sizes
//! are capped ([`MAX_JOINTS`], [`MAX_VALUES`]) so that no file makes the reader exhaust memory.

use std::collections::HashMap;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::channels::{Channel, rotation_from_channels};
use super::error::BvhError;

/// The most joints a file may declare (a full-body skeleton with fingers and a face has a few
/// hundred).
pub const MAX_JOINTS: usize = 1024;

/// The most channel values (frames times channels) a file may hold: 400 MB as `f64`, an hour at
/// 120 Hz of a 96-channel skeleton.
pub const MAX_VALUES: usize = 50_000_000;

/// A joint as declared: its place in the tree, rest offset and channels (in file units and axes).
#[derive(Clone, Debug, PartialEq)]
pub struct BvhJoint {
    pub name: String,
    /// The parent's index; `None` for a root.
    pub parent: Option<usize>,
    /// The joint's origin in its parent's frame in the rest pose.
    pub offset: Vector3<f64>,
    pub channels: Vec<Channel>,
    /// Where this joint's values start in a frame.
    pub first_value: usize,
    /// The line of its `ROOT` or `JOINT`.
    pub line: usize,
}

/// An End Site: the far end of a leaf joint's bone (not a joint: it has no channels).
#[derive(Clone, Debug, PartialEq)]
pub struct EndSite {
    pub joint: usize,
    /// In the joint's frame.
    pub offset: Vector3<f64>,
}

/// A BVH file as read: joints in file order (parents first), End Sites and the frames' values.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhFile {
    pub joints: Vec<BvhJoint>,
    pub end_sites: Vec<EndSite>,
    /// Seconds between frames.
    pub frame_time: f64,
    /// Values per frame (every joint's channels).
    pub channel_count: usize,
    /// `[frame * channel_count + value]`, degrees for rotations.
    values: Vec<f64>,
}

impl BvhFile {
    pub fn num_frames(&self) -> usize {
        self.values
            .len()
            .checked_div(self.channel_count)
            .unwrap_or(0)
    }

    /// Every channel value of `frame`, in file order.
    pub fn frame(&self, frame: usize) -> &[f64] {
        &self.values[frame * self.channel_count..(frame + 1) * self.channel_count]
    }

    fn joint_values(&self, j: usize, frame: usize) -> impl Iterator<Item = (Channel, f64)> + '_ {
        let joint = &self.joints[j];
        let values = &self.frame(frame)[joint.first_value..];
        joint.channels.iter().copied().zip(values.iter().copied())
    }

    /// Joint `j`'s rotation at `frame` relative to its parent (its rotation channels in their
    /// order), in the file's axes.
    pub fn rotation(&self, j: usize, frame: usize) -> UnitQuaternion<f64> {
        let channels: Vec<(Channel, f64)> = self
            .joint_values(j, frame)
            .map(|(c, v)| (c, v.to_radians()))
            .collect();
        rotation_from_channels(&channels)
    }

    /// Joint `j`'s origin in its parent's frame at `frame`, in file units and axes: its OFFSET,
    /// each component given by a position channel replaced by that channel's value (position
    /// channels hold the joint's translation, as Blender and MotionBuilder read them; a root's
    /// OFFSET is thus ignored where it has all three).
    pub fn translation(&self, j: usize, frame: usize) -> Vector3<f64> {
        let mut t = self.joints[j].offset;
        for (channel, v) in self.joint_values(j, frame) {
            if !channel.is_rotation() {
                t[channel.axis()] = v;
            }
        }
        t
    }

    /// Every joint's pose in the file's world at `frame` (file units and axes).
    pub fn world_poses(&self, frame: usize) -> Vec<Isometry3<f64>> {
        let mut poses: Vec<Isometry3<f64>> = Vec::with_capacity(self.joints.len());
        for (j, joint) in self.joints.iter().enumerate() {
            let local = Isometry3::from_parts(
                Translation3::from(self.translation(j, frame)),
                self.rotation(j, frame),
            );
            poses.push(match joint.parent {
                Some(p) => poses[p] * local,
                None => local,
            });
        }
        poses
    }
}

/// A word of the text and where it is.
#[derive(Clone, Copy)]
struct Token<'a> {
    text: &'a str,
    line: usize,
    column: usize,
}

impl Token<'_> {
    fn is(&self, keyword: &str) -> bool {
        self.text.eq_ignore_ascii_case(keyword)
    }
}

/// The next whitespace-separated word of `line` at or after byte `from`: its byte offset and
/// text.
fn next_word(line: &str, from: usize) -> Option<(usize, &str)> {
    let rest = line.get(from..)?;
    let start = from + rest.find(|c: char| !c.is_whitespace())?;
    let len = line[start..]
        .find(char::is_whitespace)
        .unwrap_or(line.len() - start);
    Some((start, &line[start..start + len]))
}

/// The 1-based character column of byte `offset` of `line`.
fn column(line: &str, offset: usize) -> usize {
    line.get(..offset).map_or(0, |s| s.chars().count()) + 1
}

/// The words of the text in order, with their lines.
struct Tokens<'a> {
    lines: std::iter::Enumerate<std::str::Lines<'a>>,
    line: &'a str,
    line_number: usize,
    pos: usize,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str) -> Tokens<'a> {
        Tokens {
            lines: text.lines().enumerate(),
            line: "",
            line_number: 1,
            pos: 0,
        }
    }

    fn next(&mut self) -> Option<Token<'a>> {
        loop {
            if let Some((start, text)) = next_word(self.line, self.pos) {
                self.pos = start + text.len();
                return Some(Token {
                    text,
                    line: self.line_number,
                    column: column(self.line, start),
                });
            }
            let (i, line) = self.lines.next()?;
            self.line = line;
            self.line_number = i + 1;
            self.pos = 0;
        }
    }

    /// Whether the current line has more words.
    fn line_has_more(&self) -> bool {
        next_word(self.line, self.pos).is_some()
    }
}

/// A block being read: a joint or an End Site.
enum Open {
    Joint {
        index: usize,
        has_offset: bool,
        has_channels: bool,
    },
    EndSite {
        index: usize,
        line: usize,
        has_offset: bool,
    },
}

struct Parser<'a> {
    file: &'a str,
    tokens: Tokens<'a>,
}

impl<'a> Parser<'a> {
    fn syntax(&self, line: usize, problem: String) -> BvhError {
        BvhError::Syntax {
            file: self.file.to_string(),
            line,
            problem,
        }
    }

    fn value_error(&self, token: &Token<'_>, problem: String) -> BvhError {
        BvhError::Value {
            file: self.file.to_string(),
            line: token.line,
            column: token.column,
            problem,
        }
    }

    /// The next word; at the end of the file, an error saying what was expected.
    fn next(&mut self, expected: &str) -> Result<Token<'a>, BvhError> {
        self.tokens.next().ok_or_else(|| {
            self.syntax(
                self.tokens.line_number,
                format!("the file ends where {expected} was expected"),
            )
        })
    }

    fn number(&mut self, what: &str) -> Result<f64, BvhError> {
        let token = self.next(what)?;
        finite_number(token.text)
            .map_err(|problem| self.value_error(&token, format!("{what}: {problem}")))
    }

    fn expect_keyword(&mut self, keyword: &str, after: &str) -> Result<Token<'a>, BvhError> {
        let token = self.next(&format!("{keyword} after {after}"))?;
        if token.is(keyword) {
            Ok(token)
        } else {
            Err(self.syntax(
                token.line,
                format!("expected {keyword} after {after}, found {:?}", token.text),
            ))
        }
    }
}

/// A finite number, or why `text` is not one.
fn finite_number(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("{text:?} is not a finite number")),
        Err(_) => Err(format!("{text:?} is not a number")),
    }
}

fn is_keyword(text: &str) -> bool {
    [
        "ROOT", "JOINT", "End", "OFFSET", "CHANNELS", "MOTION", "{", "}",
    ]
    .iter()
    .any(|k| text.eq_ignore_ascii_case(k))
}

/// Parses BVH text; `file` names it in errors.
pub fn read_bvh(text: &str, file: &str) -> Result<BvhFile, BvhError> {
    let mut p = Parser {
        file,
        tokens: Tokens::new(text),
    };
    let first = p.tokens.next().ok_or_else(|| {
        p.syntax(
            1,
            "the file is empty; a BVH file starts with HIERARCHY".into(),
        )
    })?;
    if !first.is("HIERARCHY") {
        return Err(p.syntax(
            first.line,
            format!(
                "expected HIERARCHY, found {:?}; is this a BVH file?",
                first.text
            ),
        ));
    }
    let mut joints: Vec<BvhJoint> = Vec::new();
    let mut end_sites: Vec<EndSite> = Vec::new();
    let mut lines_of: HashMap<String, usize> = HashMap::new();
    let mut stack: Vec<Open> = Vec::new();
    let mut values = 0;
    let motion_line = loop {
        let token = match p.tokens.next() {
            Some(t) => t,
            None => {
                let problem = match stack.last() {
                    Some(Open::Joint { index, .. }) => format!(
                        "the file ends inside joint {} (opened on line {}): a }} is missing",
                        joints[*index].name, joints[*index].line
                    ),
                    Some(Open::EndSite { line, .. }) => format!(
                        "the file ends inside the End Site opened on line {line}: a }} is missing"
                    ),
                    None => "the file ends before MOTION: a BVH file has a MOTION section".into(),
                };
                return Err(p.syntax(p.tokens.line_number, problem));
            }
        };
        let line = token.line;
        let inside = stack.last().map(|open| match open {
            Open::Joint { index, .. } => format!("joint {}", joints[*index].name),
            Open::EndSite { index, .. } => format!("the End Site of {}", joints[*index].name),
        });
        if token.is("ROOT") || token.is("JOINT") {
            let keyword = if token.is("ROOT") { "ROOT" } else { "JOINT" };
            let parent = match (keyword, stack.last()) {
                ("ROOT", None) => None,
                ("ROOT", Some(_)) => {
                    return Err(p.syntax(
                        line,
                        format!(
                            "ROOT inside {}; a child joint is a JOINT",
                            inside.unwrap_or_default()
                        ),
                    ));
                }
                (_, None) => {
                    return Err(p.syntax(
                        line,
                        "JOINT outside any joint; the hierarchy starts with ROOT".into(),
                    ));
                }
                (_, Some(Open::EndSite { .. })) => {
                    return Err(p.syntax(
                        line,
                        format!(
                            "JOINT inside {}; End Sites have no children",
                            inside.unwrap_or_default()
                        ),
                    ));
                }
                (_, Some(Open::Joint { index, .. })) => Some(*index),
            };
            let name = p.next(&format!("the name of the {keyword}"))?;
            if is_keyword(name.text) {
                return Err(p.syntax(
                    line,
                    format!("{keyword} needs a name, found {:?}", name.text),
                ));
            }
            if let Some(first) = lines_of.get(name.text) {
                return Err(p.syntax(
                    line,
                    format!(
                        "a second joint named {:?} (the first is on line {first}); joint names must differ",
                        name.text
                    ),
                ));
            }
            if joints.len() == MAX_JOINTS {
                return Err(p.syntax(
                    line,
                    format!("more than {MAX_JOINTS} joints; the reader takes at most {MAX_JOINTS}"),
                ));
            }
            p.expect_keyword("{", &format!("{keyword} {}", name.text))?;
            lines_of.insert(name.text.to_string(), line);
            joints.push(BvhJoint {
                name: name.text.to_string(),
                parent,
                offset: Vector3::zeros(),
                channels: Vec::new(),
                first_value: values,
                line,
            });
            stack.push(Open::Joint {
                index: joints.len() - 1,
                has_offset: false,
                has_channels: false,
            });
        } else if token.is("End") {
            p.expect_keyword("Site", "End")?;
            let Some(Open::Joint { index, .. }) = stack.last() else {
                return Err(p.syntax(
                    line,
                    format!(
                        "End Site outside a joint{}",
                        inside.map(|i| format!(" (inside {i})")).unwrap_or_default()
                    ),
                ));
            };
            let index = *index;
            p.expect_keyword("{", "End Site")?;
            stack.push(Open::EndSite {
                index,
                line,
                has_offset: false,
            });
        } else if token.is("OFFSET") {
            let offset = Vector3::new(
                p.number("OFFSET x")?,
                p.number("OFFSET y")?,
                p.number("OFFSET z")?,
            );
            match stack.last_mut() {
                Some(Open::Joint {
                    index, has_offset, ..
                }) => {
                    if *has_offset {
                        return Err(p.syntax(
                            line,
                            format!("a second OFFSET in joint {}", joints[*index].name),
                        ));
                    }
                    *has_offset = true;
                    joints[*index].offset = offset;
                }
                Some(Open::EndSite {
                    index, has_offset, ..
                }) => {
                    if *has_offset {
                        return Err(p.syntax(
                            line,
                            format!("a second OFFSET in the End Site of {}", joints[*index].name),
                        ));
                    }
                    *has_offset = true;
                    end_sites.push(EndSite {
                        joint: *index,
                        offset,
                    });
                }
                None => return Err(p.syntax(line, "OFFSET outside a joint".into())),
            }
        } else if token.is("CHANNELS") {
            let index = match stack.last_mut() {
                Some(Open::Joint {
                    index,
                    has_channels,
                    ..
                }) => {
                    if *has_channels {
                        return Err(p.syntax(
                            line,
                            format!("a second CHANNELS in joint {}", joints[*index].name),
                        ));
                    }
                    *has_channels = true;
                    *index
                }
                Some(Open::EndSite { .. }) => {
                    return Err(p.syntax(
                        line,
                        "CHANNELS in an End Site; End Sites have no channels".into(),
                    ));
                }
                None => return Err(p.syntax(line, "CHANNELS outside a joint".into())),
            };
            let count_token = p.next("the channel count")?;
            let count: usize = match count_token.text.parse() {
                Ok(n) if n <= 6 => n,
                Ok(_) | Err(_) if count_token.text.bytes().all(|b| b.is_ascii_digit()) => {
                    return Err(p.syntax(
                        line,
                        format!(
                            "CHANNELS {}: a joint has at most 6 channels (3 positions and 3 rotations)",
                            count_token.text
                        ),
                    ));
                }
                _ => {
                    return Err(p.value_error(
                        &count_token,
                        format!(
                            "CHANNELS needs a channel count (0 to 6), found {:?}",
                            count_token.text
                        ),
                    ));
                }
            };
            let mut channels = Vec::with_capacity(count);
            for listed in 0..count {
                let name = p.next("a channel name")?;
                let Some(channel) = Channel::from_name(name.text) else {
                    if name.line != line || is_keyword(name.text) {
                        return Err(
                            p.syntax(line, format!("CHANNELS {count} lists {listed} channels"))
                        );
                    }
                    return Err(p.value_error(
                        &name,
                        format!(
                            "unknown channel {:?}; channels are Xposition, Yposition, Zposition, Xrotation, Yrotation and Zrotation",
                            name.text
                        ),
                    ));
                };
                if channels.contains(&channel) {
                    return Err(p.value_error(
                        &name,
                        format!("channel {channel} twice in joint {}", joints[index].name),
                    ));
                }
                channels.push(channel);
            }
            joints[index].first_value = values;
            joints[index].channels = channels;
            values += count;
        } else if token.is("}") {
            match stack.pop() {
                Some(Open::Joint {
                    index,
                    has_offset: false,
                    ..
                }) => {
                    return Err(p.syntax(
                        joints[index].line,
                        format!("joint {} has no OFFSET", joints[index].name),
                    ));
                }
                Some(Open::EndSite {
                    line,
                    has_offset: false,
                    ..
                }) => {
                    return Err(p.syntax(line, "End Site has no OFFSET".into()));
                }
                Some(_) => {}
                None => return Err(p.syntax(line, "a } that closes nothing".into())),
            }
        } else if token.is("MOTION") {
            if let Some(inside) = inside {
                return Err(p.syntax(line, format!("MOTION inside {inside}: a }} is missing")));
            }
            if joints.is_empty() {
                return Err(p.syntax(
                    line,
                    "the hierarchy has no joints (no ROOT before MOTION)".into(),
                ));
            }
            break line;
        } else {
            let expected = if stack.is_empty() {
                "ROOT or MOTION"
            } else {
                "JOINT, End Site, OFFSET, CHANNELS or }"
            };
            return Err(p.syntax(
                line,
                format!("unexpected {:?}; expected {expected}", token.text),
            ));
        }
    };
    if values == 0 {
        return Err(p.syntax(
            motion_line,
            "the hierarchy declares no CHANNELS, so its frames carry no motion".into(),
        ));
    }

    let frames_token = p.expect_keyword("Frames:", "MOTION")?;
    let count_token = p.next("the frame count")?;
    let frames: usize = count_token.text.parse().map_err(|_| {
        p.value_error(
            &count_token,
            format!(
                "Frames: needs a whole number of frames, found {:?}",
                count_token.text
            ),
        )
    })?;
    let frames_line = frames_token.line;
    if frames.checked_mul(values).is_none_or(|n| n > MAX_VALUES) {
        return Err(p.syntax(
            frames_line,
            format!(
                "{frames} frames of {values} channels; the reader takes at most {MAX_VALUES} values (split the take)"
            ),
        ));
    }
    let frame_token = p.expect_keyword("Frame", "the frame count")?;
    p.expect_keyword("Time:", "Frame")?;
    let time_token = p.next("the frame time")?;
    let frame_time = match finite_number(time_token.text) {
        Ok(t) if t > 0.0 => t,
        Ok(_) => {
            return Err(p.value_error(
                &time_token,
                format!(
                    "Frame Time: {}: the time between frames must be a positive number of seconds",
                    time_token.text
                ),
            ));
        }
        Err(problem) => return Err(p.value_error(&time_token, format!("Frame Time: {problem}"))),
    };
    if p.tokens.line_has_more() {
        return Err(p.syntax(
            frame_token.line,
            "more after the frame time; the frames start on the next line".into(),
        ));
    }
    let owners: Vec<(usize, Channel)> = joints
        .iter()
        .enumerate()
        .flat_map(|(j, joint)| joint.channels.iter().map(move |&c| (j, c)))
        .collect();
    // Each value takes at least two bytes of text (a digit and a separator): a header's count
    // alone does not make the reader allocate.
    let mut data: Vec<f64> = Vec::with_capacity((frames * values).min(text.len() / 2));
    let mut read = 0;
    for (i, line) in text.lines().enumerate().skip(time_token.line) {
        let line_number = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        if read == frames {
            return Err(p.syntax(
                line_number,
                format!("more frames than the {frames} the header declares (line {frames_line})"),
            ));
        }
        let mut n = 0;
        let mut pos = 0;
        while let Some((start, word)) = next_word(line, pos) {
            pos = start + word.len();
            if n == values {
                let total = n
                    + 1
                    + std::iter::from_fn(|| {
                        let (s, w) = next_word(line, pos)?;
                        pos = s + w.len();
                        Some(())
                    })
                    .count();
                return Err(p.syntax(
                    line_number,
                    format!(
                        "frame {} has {total} values; the hierarchy declares {values} channels",
                        read + 1
                    ),
                ));
            }
            let v = finite_number(word).map_err(|problem| {
                let (j, channel) = owners[n];
                BvhError::Value {
                    file: file.to_string(),
                    line: line_number,
                    column: column(line, start),
                    problem: format!(
                        "frame {}, {} of joint {}: {problem}",
                        read + 1,
                        channel,
                        joints[j].name
                    ),
                }
            })?;
            data.push(v);
            n += 1;
        }
        if n < values {
            return Err(p.syntax(
                line_number,
                format!("frame {} has {n} of {values} values", read + 1),
            ));
        }
        read += 1;
    }
    if read < frames {
        return Err(p.syntax(
            frames_line,
            format!("the header says {frames} frames, the file has {read}"),
        ));
    }
    Ok(BvhFile {
        joints,
        end_sites,
        frame_time,
        channel_count: values,
        values: data,
    })
}
