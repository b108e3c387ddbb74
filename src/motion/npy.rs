//! NumPy's `.npy` arrays, as `.npz` archives hold them (`super::npz`): the header (magic, version,
//! a Python dict literal with `descr`, `fortran_order` and `shape`) and the data, for the element
//! types motion files use: floats (`f4`, `f8`), integers (`i1`..`i8`, `u1`..`u8`) and unicode
//! strings (`U<n>`, UTF-32), either byte order. <https://numpy.org/doc/stable/reference/generated/numpy.lib.format.html>
//!
//! Every length read from a file is bounded before anything is allocated from it: the header by
//! [`MAX_HEADER_LEN`], the data by the bytes actually present (the shape's element count times
//! the element size, computed with checked arithmetic, must equal them).

/// The longest header accepted (NumPy itself refuses headers over 10 000 bytes by default).
pub const MAX_HEADER_LEN: usize = 1 << 16;

/// The most dimensions accepted (NumPy's own limit is 64).
pub const MAX_DIMENSIONS: usize = 64;

/// The longest unicode element accepted, in code points.
pub const MAX_STRING_LEN: usize = 4096;

const MAGIC: &[u8] = b"\x93NUMPY";

/// The values of an array, in C (row-major) order.
#[derive(Debug, Clone, PartialEq)]
pub enum NpyValues {
    /// `f4` or `f8`, as f64 (an `f4` converts exactly).
    Float(Vec<f64>),
    /// `i1`..`i8`, `u1`..`u8`, as i64.
    Int(Vec<i64>),
    /// `U<n>`, trailing NULs removed (NumPy pads shorter strings with them).
    Unicode(Vec<String>),
}

/// An array read from a `.npy` file.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    /// The NumPy type string as the header gives it (e.g. `<f8`), for messages.
    pub descr: String,
    pub shape: Vec<usize>,
    pub values: NpyValues,
}

impl NpyArray {
    /// The number of elements (the product of the shape).
    pub fn len(&self) -> usize {
        match &self.values {
            NpyValues::Float(v) => v.len(),
            NpyValues::Int(v) => v.len(),
            NpyValues::Unicode(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The kind and size of an element, from the type string.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ElementType {
    Float {
        size: usize,
        big_endian: bool,
    },
    Int {
        size: usize,
        big_endian: bool,
        signed: bool,
    },
    Unicode {
        chars: usize,
        big_endian: bool,
    },
}

impl ElementType {
    fn size(self) -> usize {
        match self {
            ElementType::Float { size, .. } | ElementType::Int { size, .. } => size,
            ElementType::Unicode { chars, .. } => 4 * chars,
        }
    }
}

/// Parses a type string: byte order (`<`, `>`, `=`, `|`), kind and size.
fn element_type(descr: &str) -> Result<ElementType, String> {
    let unsupported = || {
        format!(
            "the element type {descr:?} is not supported (expected floats f4/f8, integers or \
             unicode strings U<n>)"
        )
    };
    let mut chars = descr.chars();
    let order = chars.next().ok_or_else(unsupported)?;
    // `=` is the native order; NumPy writes `<` on little-endian machines, this crate's targets.
    let big_endian = match order {
        '<' | '=' | '|' => false,
        '>' => true,
        _ => return Err(unsupported()),
    };
    let kind = chars.next().ok_or_else(unsupported)?;
    let size: usize = chars.as_str().parse().map_err(|_| unsupported())?;
    match (kind, size) {
        ('f', 4 | 8) => Ok(ElementType::Float { size, big_endian }),
        ('i' | 'u', 1 | 2 | 4 | 8) => Ok(ElementType::Int {
            size,
            big_endian,
            signed: kind == 'i',
        }),
        ('U', 1..=MAX_STRING_LEN) => Ok(ElementType::Unicode {
            chars: size,
            big_endian,
        }),
        _ => Err(unsupported()),
    }
}

/// The fields of a header: `{'descr': '<f8', 'fortran_order': False, 'shape': (325, 36), }`.
#[derive(Debug, Default)]
struct Header {
    descr: Option<String>,
    fortran_order: Option<bool>,
    shape: Option<Vec<usize>>,
}

/// A reader of the Python literal subset a header uses: a dict of string keys to strings,
/// `True`/`False` and tuples of integers. Anything else is refused (structured dtypes are lists).
struct Literal<'a> {
    text: &'a [u8],
    at: usize,
}

impl Literal<'_> {
    fn skip_space(&mut self) {
        while self
            .text
            .get(self.at)
            .is_some_and(|c| c.is_ascii_whitespace())
        {
            self.at += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.skip_space();
        self.text.get(self.at).copied()
    }

    fn expect(&mut self, c: u8) -> Result<(), String> {
        if self.peek() == Some(c) {
            self.at += 1;
            Ok(())
        } else {
            Err(format!(
                "the header is not a Python dict literal: expected {:?} at byte {}",
                c as char, self.at
            ))
        }
    }

    fn string(&mut self) -> Result<String, String> {
        let quote = match self.peek() {
            Some(q @ (b'\'' | b'"')) => q,
            _ => {
                return Err(format!(
                    "expected a string at byte {} of the header",
                    self.at
                ));
            }
        };
        let start = self.at + 1;
        let len = self.text[start..]
            .iter()
            .position(|&c| c == quote || c == b'\\')
            .ok_or_else(|| "a string of the header is not closed".to_string())?;
        let end = start + len;
        if self.text[end] == b'\\' {
            return Err("escapes in the header's strings are not supported".to_string());
        }
        self.at = end + 1;
        String::from_utf8(self.text[start..end].to_vec())
            .map_err(|_| "a string of the header is not UTF-8".to_string())
    }

    fn word(&mut self) -> &[u8] {
        self.skip_space();
        let start = self.at;
        while self
            .text
            .get(self.at)
            .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
        {
            self.at += 1;
        }
        &self.text[start..self.at]
    }

    fn boolean(&mut self) -> Result<bool, String> {
        match self.word() {
            b"True" => Ok(true),
            b"False" => Ok(false),
            _ => Err("`fortran_order` must be True or False".to_string()),
        }
    }

    fn shape(&mut self) -> Result<Vec<usize>, String> {
        self.expect(b'(')?;
        let mut shape = Vec::new();
        loop {
            if self.peek() == Some(b')') {
                self.at += 1;
                return Ok(shape);
            }
            if shape.len() == MAX_DIMENSIONS {
                return Err(format!(
                    "the shape has more than {MAX_DIMENSIONS} dimensions"
                ));
            }
            let word = self.word();
            // Python 2's NumPy wrote long integers with a trailing L.
            let digits = word.strip_suffix(b"L").unwrap_or(word);
            let dim = std::str::from_utf8(digits)
                .ok()
                .filter(|d| !d.is_empty() && d.bytes().all(|c| c.is_ascii_digit()))
                .and_then(|d| d.parse::<usize>().ok())
                .ok_or_else(|| "the shape must be a tuple of non-negative integers".to_string())?;
            shape.push(dim);
            if self.peek() == Some(b',') {
                self.at += 1;
            } else {
                self.expect(b')')?;
                return Ok(shape);
            }
        }
    }

    fn header(&mut self) -> Result<Header, String> {
        let mut header = Header::default();
        self.expect(b'{')?;
        loop {
            if self.peek() == Some(b'}') {
                break;
            }
            let key = self.string()?;
            self.expect(b':')?;
            let duplicate = match key.as_str() {
                "descr" => header.descr.replace(self.string()?).is_some(),
                "fortran_order" => header.fortran_order.replace(self.boolean()?).is_some(),
                "shape" => header.shape.replace(self.shape()?).is_some(),
                _ => return Err(format!("the header has the unknown key {key:?}")),
            };
            if duplicate {
                return Err(format!("the header gives {key:?} twice"));
            }
            if self.peek() == Some(b',') {
                self.at += 1;
            } else {
                break;
            }
        }
        self.expect(b'}')?;
        if self.peek().is_some() {
            return Err("the header has text after its dict".to_string());
        }
        Ok(header)
    }
}

/// Splits a `.npy` file into its header text and its data.
fn split(bytes: &[u8]) -> Result<(&[u8], &[u8]), String> {
    let rest = bytes
        .strip_prefix(MAGIC)
        .ok_or_else(|| "not a .npy array (no \\x93NUMPY magic)".to_string())?;
    let (&[major, _minor], rest) = rest
        .split_first_chunk::<2>()
        .ok_or_else(|| "the .npy header is cut short".to_string())?;
    let (len, rest) = match major {
        1 => rest
            .split_first_chunk::<2>()
            .map(|(len, rest)| (u16::from_le_bytes(*len) as usize, rest)),
        2 | 3 => rest
            .split_first_chunk::<4>()
            .map(|(len, rest)| (u32::from_le_bytes(*len) as usize, rest)),
        _ => {
            return Err(format!(
                ".npy format version {major} is not supported (1 to 3 are)"
            ));
        }
    }
    .ok_or_else(|| "the .npy header is cut short".to_string())?;
    if len > MAX_HEADER_LEN {
        return Err(format!(
            "the .npy header claims {len} bytes, more than the {MAX_HEADER_LEN} accepted"
        ));
    }
    if len > rest.len() {
        return Err(format!(
            "the .npy header claims {len} bytes, the file has {} after it",
            rest.len()
        ));
    }
    Ok(rest.split_at(len))
}

/// Reads a `.npy` file held in memory.
pub fn parse(bytes: &[u8]) -> Result<NpyArray, String> {
    let (text, data) = split(bytes)?;
    let header = Literal { text, at: 0 }.header()?;
    let descr = header
        .descr
        .ok_or_else(|| "the header has no 'descr'".to_string())?;
    let shape = header
        .shape
        .ok_or_else(|| "the header has no 'shape'".to_string())?;
    let fortran_order = header
        .fortran_order
        .ok_or_else(|| "the header has no 'fortran_order'".to_string())?;
    let element = element_type(&descr)?;
    let count = shape
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| format!("the shape {shape:?} has too many elements"))?;
    let needed = count.checked_mul(element.size());
    if needed != Some(data.len()) {
        return Err(format!(
            "the shape {shape:?} of {descr} needs {} bytes of data, the array has {}",
            needed.map_or_else(|| "more than 2^64".to_string(), |n| n.to_string()),
            data.len()
        ));
    }
    let chunks = data.chunks_exact(element.size().max(1));
    let mut values = match element {
        ElementType::Float { size, big_endian } => {
            NpyValues::Float(chunks.map(|c| float(c, size, big_endian)).collect())
        }
        ElementType::Int {
            size,
            big_endian,
            signed,
        } => NpyValues::Int(
            chunks
                .map(|c| int(c, size, big_endian, signed))
                .collect::<Result<_, _>>()?,
        ),
        ElementType::Unicode { big_endian, .. } => NpyValues::Unicode(
            chunks
                .map(|c| unicode(c, big_endian))
                .collect::<Result<_, _>>()?,
        ),
    };
    if fortran_order && shape.len() > 1 {
        values = to_c_order(values, &shape);
    }
    Ok(NpyArray {
        descr,
        shape,
        values,
    })
}

fn float(bytes: &[u8], size: usize, big_endian: bool) -> f64 {
    let mut b = [0u8; 8];
    b[..size].copy_from_slice(bytes);
    if big_endian {
        b[..size].reverse();
    }
    if size == 4 {
        f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64
    } else {
        f64::from_le_bytes(b)
    }
}

fn int(bytes: &[u8], size: usize, big_endian: bool, signed: bool) -> Result<i64, String> {
    let mut b = [0u8; 8];
    b[..size].copy_from_slice(bytes);
    if big_endian {
        b[..size].reverse();
    }
    // Sign-extend a negative signed value.
    if signed && b[size - 1] & 0x80 != 0 {
        b[size..].fill(0xff);
    }
    if signed {
        Ok(i64::from_le_bytes(b))
    } else {
        i64::try_from(u64::from_le_bytes(b))
            .map_err(|_| format!("the integer {} is too large", u64::from_le_bytes(b)))
    }
}

fn unicode(bytes: &[u8], big_endian: bool) -> Result<String, String> {
    let mut text = String::with_capacity(bytes.len() / 4);
    for c in bytes.chunks_exact(4) {
        let c = [c[0], c[1], c[2], c[3]];
        let code = if big_endian {
            u32::from_be_bytes(c)
        } else {
            u32::from_le_bytes(c)
        };
        text.push(
            char::from_u32(code)
                .ok_or_else(|| format!("a string holds {code:#x}, which is not a character"))?,
        );
    }
    Ok(text.trim_end_matches('\0').to_string())
}

/// The values of a Fortran-order (column-major) array, reordered to C order.
fn to_c_order(values: NpyValues, shape: &[usize]) -> NpyValues {
    fn reorder<T: Clone>(v: Vec<T>, shape: &[usize]) -> Vec<T> {
        // Element at C multi-index (i0, .., ik) sits at i0 + d0 (i1 + d1 (i2 + ..)) in Fortran order.
        let mut index = vec![0usize; shape.len()];
        let mut out = Vec::with_capacity(v.len());
        for _ in 0..v.len() {
            let at = index
                .iter()
                .zip(shape)
                .rev()
                .fold(0, |acc, (&i, &d)| acc * d + i);
            out.push(v[at].clone());
            for (i, &d) in index.iter_mut().zip(shape).rev() {
                *i += 1;
                if *i < d {
                    break;
                }
                *i = 0;
            }
        }
        out
    }
    match values {
        NpyValues::Float(v) => NpyValues::Float(reorder(v, shape)),
        NpyValues::Int(v) => NpyValues::Int(reorder(v, shape)),
        NpyValues::Unicode(v) => NpyValues::Unicode(reorder(v, shape)),
    }
}

/// The bytes of a `.npy` file (format 1.0, little-endian, C order) holding `values` of `shape`:
/// what NumPy's `np.save` writes, for tests and tools that write motion files.
pub fn to_bytes(shape: &[usize], values: &NpyValues) -> Vec<u8> {
    let (descr, data): (String, Vec<u8>) = match values {
        NpyValues::Float(v) => (
            "<f8".into(),
            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        ),
        NpyValues::Int(v) => (
            "<i8".into(),
            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        ),
        NpyValues::Unicode(v) => {
            let chars = v
                .iter()
                .map(|s| s.chars().count())
                .max()
                .unwrap_or(0)
                .max(1);
            let data = v
                .iter()
                .flat_map(|s| {
                    let mut codes: Vec<u32> = s.chars().map(u32::from).collect();
                    codes.resize(chars, 0);
                    codes.into_iter().flat_map(u32::to_le_bytes)
                })
                .collect();
            (format!("<U{chars}"), data)
        }
    };
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_text}, }}");
    // NumPy pads the header with spaces so that the data starts at a multiple of 64 bytes.
    let unpadded = MAGIC.len() + 4 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut bytes = MAGIC.to_vec();
    bytes.extend_from_slice(&[1, 0]);
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    bytes.extend_from_slice(&data);
    bytes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_strings_and_ints_round_trip() {
        let floats = NpyValues::Float(vec![1.5, -2.0, f64::MIN_POSITIVE, 7.0, 8.0, 9.0]);
        let bytes = to_bytes(&[2, 3], &floats);
        assert_eq!((bytes.len() - 6 * 8) % 64, 0, "data aligned to 64 bytes");
        let array = parse(&bytes).expect("parses");
        assert_eq!(
            (array.shape.as_slice(), &array.values),
            (&[2, 3][..], &floats)
        );
        let names = NpyValues::Unicode(vec!["left_hip".into(), "αβ".into()]);
        let array = parse(&to_bytes(&[2], &names)).expect("parses");
        assert_eq!((array.descr.as_str(), &array.values), ("<U8", &names));
        let ints = NpyValues::Int(vec![50]);
        assert_eq!(parse(&to_bytes(&[1], &ints)).expect("parses").values, ints);
    }

    fn with_header(header: &str, data: &[u8]) -> Vec<u8> {
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&[1, 0]);
        bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(data);
        bytes
    }

    #[test]
    fn reads_float32_big_endian_and_fortran_order() {
        let data: Vec<u8> = [1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0]
            .iter()
            .flat_map(|x| x.to_be_bytes())
            .collect();
        let bytes = with_header(
            "{'descr': '>f4', 'fortran_order': True, 'shape': (2L, 3L)}\n",
            &data,
        );
        let array = parse(&bytes).expect("parses");
        // Column-major [1 2 3 4 5 6] of a 2x3 array is [[1, 3, 5], [2, 4, 6]].
        assert_eq!(
            array.values,
            NpyValues::Float(vec![1.0, 3.0, 5.0, 2.0, 4.0, 6.0])
        );
        let negative = with_header(
            "{'descr': '<i2', 'fortran_order': False, 'shape': (1,)}",
            &(-3i16).to_le_bytes(),
        );
        assert_eq!(
            parse(&negative).expect("parses").values,
            NpyValues::Int(vec![-3])
        );
    }

    #[test]
    fn refuses_bad_headers_without_allocating_from_them() {
        let cases: [(Vec<u8>, &str); 7] = [
            (b"PK\x03\x04".to_vec(), "magic"),
            (
                [MAGIC, &[2, 0], &u32::MAX.to_le_bytes()].concat(),
                "claims 4294967295 bytes",
            ),
            (
                with_header(
                    "{'descr': '<f8', 'fortran_order': False, 'shape': (4294967296, 4294967296, 2)}",
                    &[],
                ),
                "too many elements",
            ),
            (
                with_header(
                    "{'descr': '<f8', 'fortran_order': False, 'shape': (3,)}",
                    &[0; 16],
                ),
                "needs 24 bytes",
            ),
            (
                with_header(
                    "{'descr': [('a', '<f8')], 'fortran_order': False, 'shape': (1,)}",
                    &[0; 8],
                ),
                "expected a string",
            ),
            (
                with_header("{'descr': 'O', 'fortran_order': False, 'shape': ()}", &[]),
                "not supported",
            ),
            (
                with_header(
                    "{'descr': '<U2', 'fortran_order': False, 'shape': (1,)}",
                    &[0, 0xd8, 0, 0, 0, 0, 0, 0],
                ),
                "not a character",
            ),
        ];
        for (bytes, expected) in cases {
            let err = parse(&bytes).expect_err(expected);
            assert!(err.contains(expected), "{err} (expected {expected:?})");
        }
    }
}
