//! Launch contracts: what a kernel's launch dimension must equal or not exceed, in terms of the
//! extents of its array parameters (`"launch"` of each kernel in `ptx/env/manifest.json`,
//! declared with `@launch(...)` above the kernel in `kernels_py/env/`).
//!
//! Warp kernels do no bounds checks: a launch over more threads than the arrays have rows reads
//! and writes past them, and one over fewer leaves work undone. Every kernel therefore declares,
//! for each launch axis, one or more rules such as
//!
//! ```text
//! dim == extent(ctrl, 0) * extent(joint_kind, 0)
//! dim <= extent(qpos, 0)
//! dim[0] == cdiv(len(x), 2048)
//! dim[1] == 128
//! ```
//!
//! `dim` is the launch extent (`dim[i]` axis `i` of an N-D launch), the relation `==`, `<=` or
//! `>=` (for kernels whose surplus threads return at once: one-thread kernels are `dim >= 1`),
//! and the bound is built from non-negative integers, `extent(array, axis)`, `len(array)` (the
//! element count), `a + b`, `a * b`, `cdiv(a, b)` (ceiling division), `max(a, b)` and
//! parentheses. [`parse_rule`] turns the text into a [`Rule`] (postfix [`Op`]s naming parameters
//! by index), [`LaunchRule::check`] evaluates it against the shapes of a launch's arrays. The
//! generated launchers check every rule of their kernel before each launch (so at capture time
//! for captured launches), with an error naming the kernel, the dimension and the arrays.
//!
//! `build.rs` includes this file through `manifest.rs` (`#[path]`): std only.

/// How the launch extent relates to the bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Relation {
    /// `dim == bound`.
    Equal,
    /// `dim <= bound`.
    AtMost,
    /// `dim >= bound`: for kernels whose extra threads return at once (one-thread kernels,
    /// `if wp.tid() != 0: return`, are `dim >= 1`).
    AtLeast,
}

impl Relation {
    pub const fn symbol(self) -> &'static str {
        match self {
            Relation::Equal => "==",
            Relation::AtMost => "<=",
            Relation::AtLeast => ">=",
        }
    }

    /// The variant's name, for generated code.
    pub const fn variant(self) -> &'static str {
        match self {
            Relation::Equal => "Equal",
            Relation::AtMost => "AtMost",
            Relation::AtLeast => "AtLeast",
        }
    }
}

/// One step of a bound in postfix order: values push, operators pop two and push one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    Const(u64),
    /// Extent `axis` of array parameter `param` (an index into the kernel's parameters).
    Extent {
        param: usize,
        axis: usize,
    },
    /// Element count of array parameter `param`.
    Len {
        param: usize,
    },
    Add,
    Mul,
    /// Ceiling division; division by zero breaks the rule.
    CeilDiv,
    Max,
}

impl Op {
    /// The Rust expression of the op, for generated code (`Op` in scope).
    pub fn rust(&self) -> String {
        match *self {
            Op::Const(v) => format!("Op::Const({v})"),
            Op::Extent { param, axis } => format!("Op::Extent {{ param: {param}, axis: {axis} }}"),
            Op::Len { param } => format!("Op::Len {{ param: {param} }}"),
            Op::Add => "Op::Add".to_owned(),
            Op::Mul => "Op::Mul".to_owned(),
            Op::CeilDiv => "Op::CeilDiv".to_owned(),
            Op::Max => "Op::Max".to_owned(),
        }
    }
}

/// A rule as the generated launchers hold it (`&'static` data).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LaunchRule<'a> {
    /// The launch axis the rule constrains.
    pub axis: usize,
    pub relation: Relation,
    /// The bound, in postfix order.
    pub bound: &'a [Op],
    /// The rule as declared, for messages.
    pub text: &'a str,
}

/// A parsed rule, owning its parts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rule {
    pub axis: usize,
    pub relation: Relation,
    pub bound: Vec<Op>,
    pub text: String,
}

impl Rule {
    pub fn as_launch_rule(&self) -> LaunchRule<'_> {
        LaunchRule {
            axis: self.axis,
            relation: self.relation,
            bound: &self.bound,
            text: &self.text,
        }
    }
}

/// Why a launch breaks a rule.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Violation {
    /// The launch has no axis `axis` (it has `dims`).
    Axis { axis: usize, dims: usize },
    /// Array parameter `param` was not given (its shape is unknown).
    Missing { param: usize },
    /// Axis `axis` of array parameter `param` does not exist.
    NoAxis { param: usize, axis: usize },
    /// The bound overflows `u64` or divides by zero.
    Arithmetic,
    /// The launch extent is `dim`, the bound `bound`.
    Bound { dim: usize, bound: u64 },
}

impl LaunchRule<'_> {
    /// The array parameters the bound reads, in order of first use.
    pub fn params(&self) -> Vec<usize> {
        let mut out = Vec::new();
        for op in self.bound {
            if let Op::Extent { param, .. } | Op::Len { param } = *op
                && !out.contains(&param)
            {
                out.push(param);
            }
        }
        out
    }

    /// Evaluates the bound for arrays of shapes `shapes` (by parameter index; `None` for a
    /// parameter that is not an array or was not given).
    pub fn bound_for(&self, shapes: &[Option<&[usize]>]) -> Result<u64, Violation> {
        let shape = |param: usize| {
            shapes
                .get(param)
                .copied()
                .flatten()
                .ok_or(Violation::Missing { param })
        };
        let mut stack: Vec<u64> = Vec::with_capacity(self.bound.len());
        for op in self.bound {
            let value = match *op {
                Op::Const(v) => v,
                Op::Extent { param, axis } => {
                    let extent = shape(param)?
                        .get(axis)
                        .copied()
                        .ok_or(Violation::NoAxis { param, axis })?;
                    extent as u64
                }
                Op::Len { param } => shape(param)?
                    .iter()
                    .try_fold(1u64, |acc, &e| acc.checked_mul(e as u64))
                    .ok_or(Violation::Arithmetic)?,
                Op::Add | Op::Mul | Op::CeilDiv | Op::Max => {
                    let (Some(b), Some(a)) = (stack.pop(), stack.pop()) else {
                        return Err(Violation::Arithmetic);
                    };
                    match *op {
                        Op::Add => a.checked_add(b),
                        Op::Mul => a.checked_mul(b),
                        Op::CeilDiv => (b != 0).then(|| a.div_ceil(b)),
                        _ => Some(a.max(b)),
                    }
                    .ok_or(Violation::Arithmetic)?
                }
            };
            stack.push(value);
        }
        match stack.as_slice() {
            [value] => Ok(*value),
            _ => Err(Violation::Arithmetic),
        }
    }

    /// Checks a launch over `dim` with arrays of shapes `shapes` (by parameter index).
    pub fn check(&self, dim: &[usize], shapes: &[Option<&[usize]>]) -> Result<(), Violation> {
        let extent = *dim.get(self.axis).ok_or(Violation::Axis {
            axis: self.axis,
            dims: dim.len(),
        })?;
        let bound = self.bound_for(shapes)?;
        let holds = match self.relation {
            Relation::Equal => extent as u64 == bound,
            Relation::AtMost => extent as u64 <= bound,
            Relation::AtLeast => extent as u64 >= bound,
        };
        if holds {
            Ok(())
        } else {
            Err(Violation::Bound { dim: extent, bound })
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Token {
    Name(String),
    Int(u64),
    Symbol(&'static str),
}

fn tokenize(text: &str) -> Result<Vec<Token>, String> {
    let mut tokens = Vec::new();
    let mut chars = text.char_indices().peekable();
    while let Some(&(at, c)) = chars.peek() {
        if c.is_whitespace() {
            chars.next();
        } else if c.is_ascii_alphabetic() || c == '_' {
            let mut name = String::new();
            while let Some(&(_, c)) = chars.peek() {
                if !(c.is_ascii_alphanumeric() || c == '_') {
                    break;
                }
                name.push(c);
                chars.next();
            }
            tokens.push(Token::Name(name));
        } else if c.is_ascii_digit() {
            let mut digits = String::new();
            while let Some(&(_, c)) = chars.peek() {
                if !c.is_ascii_digit() {
                    break;
                }
                digits.push(c);
                chars.next();
            }
            let value = digits
                .parse()
                .map_err(|_| format!("the number {digits} does not fit 64 bits"))?;
            tokens.push(Token::Int(value));
        } else {
            let rest = &text[at..];
            let symbol = ["==", "<=", ">=", "(", ")", "[", "]", ",", "*", "+"]
                .into_iter()
                .find(|s| rest.starts_with(s))
                .ok_or_else(|| format!("unexpected {c:?} at byte {at}"))?;
            for _ in 0..symbol.len() {
                chars.next();
            }
            tokens.push(Token::Symbol(symbol));
        }
    }
    Ok(tokens)
}

/// What a parameter is, as far as the parser needs to know.
pub struct ParamInfo<'a> {
    pub name: &'a str,
    /// `Some(ndim)` for an array parameter.
    pub ndim: Option<usize>,
}

struct Parser<'a> {
    tokens: Vec<Token>,
    at: usize,
    params: &'a [ParamInfo<'a>],
    out: Vec<Op>,
}

impl Parser<'_> {
    fn peek(&self) -> Option<&Token> {
        self.tokens.get(self.at)
    }

    fn next(&mut self) -> Option<Token> {
        let token = self.tokens.get(self.at).cloned();
        self.at += 1;
        token
    }

    fn expect(&mut self, symbol: &'static str) -> Result<(), String> {
        match self.next() {
            Some(Token::Symbol(s)) if s == symbol => Ok(()),
            other => Err(format!("expected `{symbol}`, found {}", describe(&other))),
        }
    }

    fn int(&mut self) -> Result<u64, String> {
        match self.next() {
            Some(Token::Int(v)) => Ok(v),
            other => Err(format!("expected a number, found {}", describe(&other))),
        }
    }

    /// An array parameter's index and ndim.
    fn array(&mut self) -> Result<(usize, usize), String> {
        let name = match self.next() {
            Some(Token::Name(name)) => name,
            other => {
                return Err(format!(
                    "expected a parameter name, found {}",
                    describe(&other)
                ));
            }
        };
        let (index, param) = self
            .params
            .iter()
            .enumerate()
            .find(|(_, p)| p.name == name)
            .ok_or_else(|| format!("the kernel has no parameter {name}"))?;
        let ndim = param
            .ndim
            .ok_or_else(|| format!("parameter {name} is not an array"))?;
        Ok((index, ndim))
    }

    fn expr(&mut self) -> Result<(), String> {
        self.product()?;
        while self.peek() == Some(&Token::Symbol("+")) {
            self.next();
            self.product()?;
            self.out.push(Op::Add);
        }
        Ok(())
    }

    fn product(&mut self) -> Result<(), String> {
        self.atom()?;
        while self.peek() == Some(&Token::Symbol("*")) {
            self.next();
            self.atom()?;
            self.out.push(Op::Mul);
        }
        Ok(())
    }

    fn atom(&mut self) -> Result<(), String> {
        match self.next() {
            Some(Token::Int(v)) => self.out.push(Op::Const(v)),
            Some(Token::Symbol("(")) => {
                self.expr()?;
                self.expect(")")?;
            }
            Some(Token::Name(f)) if f == "extent" => {
                self.expect("(")?;
                let (param, ndim) = self.array()?;
                self.expect(",")?;
                let axis = self.int()? as usize;
                if axis >= ndim {
                    return Err(format!(
                        "axis {axis} of parameter {}, which has {ndim} dimension(s)",
                        self.params[param].name
                    ));
                }
                self.expect(")")?;
                self.out.push(Op::Extent { param, axis });
            }
            Some(Token::Name(f)) if f == "len" => {
                self.expect("(")?;
                let (param, _) = self.array()?;
                self.expect(")")?;
                self.out.push(Op::Len { param });
            }
            Some(Token::Name(f)) if f == "cdiv" || f == "max" => {
                self.expect("(")?;
                self.expr()?;
                self.expect(",")?;
                self.expr()?;
                self.expect(")")?;
                self.out
                    .push(if f == "cdiv" { Op::CeilDiv } else { Op::Max });
            }
            other => {
                return Err(format!(
                    "expected a number, `(`, extent(..), len(..), cdiv(..) or max(..), found {}",
                    describe(&other)
                ));
            }
        }
        Ok(())
    }
}

fn describe(token: &Option<Token>) -> String {
    match token {
        None => "the end".to_owned(),
        Some(Token::Name(n)) => format!("`{n}`"),
        Some(Token::Int(v)) => format!("`{v}`"),
        Some(Token::Symbol(s)) => format!("`{s}`"),
    }
}

/// Parses rule `text` of a kernel launched over `dims` dimensions with parameters `params`.
pub fn parse_rule(text: &str, dims: usize, params: &[ParamInfo<'_>]) -> Result<Rule, String> {
    let mut p = Parser {
        tokens: tokenize(text)?,
        at: 0,
        params,
        out: Vec::new(),
    };
    match p.next() {
        Some(Token::Name(n)) if n == "dim" => {}
        other => return Err(format!("expected `dim`, found {}", describe(&other))),
    }
    let axis = if p.peek() == Some(&Token::Symbol("[")) {
        p.next();
        let axis = p.int()? as usize;
        p.expect("]")?;
        axis
    } else if dims == 1 {
        0
    } else {
        return Err(format!(
            "a {dims}-D launch: name the axis (`dim[0]` .. `dim[{}]`)",
            dims - 1
        ));
    };
    if axis >= dims {
        return Err(format!("axis {axis} of a {dims}-D launch"));
    }
    let relation = match p.next() {
        Some(Token::Symbol("==")) => Relation::Equal,
        Some(Token::Symbol("<=")) => Relation::AtMost,
        Some(Token::Symbol(">=")) => Relation::AtLeast,
        other => {
            return Err(format!(
                "expected `==`, `<=` or `>=`, found {}",
                describe(&other)
            ));
        }
    };
    p.expr()?;
    if p.at < p.tokens.len() {
        return Err(format!(
            "unexpected {} after the bound",
            describe(&p.peek().cloned())
        ));
    }
    Ok(Rule {
        axis,
        relation,
        bound: p.out,
        text: text.to_owned(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const PARAMS: [ParamInfo<'static>; 3] = [
        ParamInfo {
            name: "x",
            ndim: Some(2),
        },
        ParamInfo {
            name: "scale",
            ndim: None,
        },
        ParamInfo {
            name: "out",
            ndim: Some(1),
        },
    ];

    fn rule(text: &str, dims: usize) -> Rule {
        parse_rule(text, dims, &PARAMS).unwrap()
    }

    #[test]
    fn rules_parse_to_postfix_with_precedence() {
        let r = rule("dim == extent(x, 0) * extent(x, 1) + 1", 1);
        assert_eq!((r.axis, r.relation), (0, Relation::Equal));
        assert_eq!(
            r.bound,
            [
                Op::Extent { param: 0, axis: 0 },
                Op::Extent { param: 0, axis: 1 },
                Op::Mul,
                Op::Const(1),
                Op::Add
            ]
        );
        let r = rule(
            "dim[1] <= cdiv(len(out), 64) * (2 + max(1, extent(x, 1)))",
            2,
        );
        assert_eq!((r.axis, r.relation), (1, Relation::AtMost));
        assert_eq!(
            r.as_launch_rule()
                .bound_for(&[Some(&[3, 5]), None, Some(&[130])]),
            Ok(3 * (2 + 5))
        );
        assert_eq!(r.as_launch_rule().params(), [2, 0]);
    }

    #[test]
    fn launches_are_checked_against_the_bound() {
        let shapes: [Option<&[usize]>; 3] = [Some(&[4, 7]), None, Some(&[28])];
        let eq = rule("dim == extent(x, 0) * extent(x, 1)", 1);
        assert_eq!(eq.as_launch_rule().check(&[28], &shapes), Ok(()));
        assert_eq!(
            eq.as_launch_rule().check(&[27], &shapes),
            Err(Violation::Bound { dim: 27, bound: 28 })
        );
        let le = rule("dim <= len(out)", 1);
        assert_eq!(le.as_launch_rule().check(&[0], &shapes), Ok(()));
        assert_eq!(le.as_launch_rule().check(&[28], &shapes), Ok(()));
        assert_eq!(
            le.as_launch_rule().check(&[29], &shapes),
            Err(Violation::Bound { dim: 29, bound: 28 })
        );
        assert_eq!(
            le.as_launch_rule().check(&[1], &[None, None, None]),
            Err(Violation::Missing { param: 2 })
        );
        assert_eq!(
            eq.as_launch_rule().check(&[1], &[Some(&[4]), None, None]),
            Err(Violation::NoAxis { param: 0, axis: 1 })
        );
        let one = rule("dim >= 1", 1);
        assert_eq!(one.as_launch_rule().check(&[64], &shapes), Ok(()));
        assert_eq!(
            one.as_launch_rule().check(&[0], &shapes),
            Err(Violation::Bound { dim: 0, bound: 1 })
        );
        let two = rule("dim[1] == 128", 2);
        assert_eq!(
            two.as_launch_rule().check(&[1], &shapes),
            Err(Violation::Axis { axis: 1, dims: 1 })
        );
        let zero = rule("dim == cdiv(len(out), extent(x, 0) * 0)", 1);
        assert_eq!(
            zero.as_launch_rule().check(&[1], &shapes),
            Err(Violation::Arithmetic)
        );
        let huge = rule("dim <= 18446744073709551615 * 2", 1);
        assert_eq!(
            huge.as_launch_rule().check(&[1], &shapes),
            Err(Violation::Arithmetic)
        );
    }

    #[test]
    fn bad_rules_say_what_is_wrong() {
        for (text, dims, expected) in [
            ("dim == len(scale)", 1, "scale is not an array"),
            ("dim == len(y)", 1, "no parameter y"),
            ("dim == extent(out, 1)", 1, "axis 1 of parameter out"),
            ("dim == 128", 2, "name the axis"),
            ("dim[2] == 128", 2, "axis 2 of a 2-D launch"),
            ("dim = 1", 1, "unexpected '='"),
            ("dim == 1 1", 1, "after the bound"),
            ("dim == (1", 1, "expected `)`"),
            ("size == 1", 1, "expected `dim`"),
            ("dim > 1", 1, "unexpected '>'"),
            ("dim == min(1, 2)", 1, "found `min`"),
            ("dim == 99999999999999999999", 1, "does not fit 64 bits"),
        ] {
            let err = parse_rule(text, dims, &PARAMS).unwrap_err();
            assert!(err.contains(expected), "{text}: {err}");
        }
    }
}
