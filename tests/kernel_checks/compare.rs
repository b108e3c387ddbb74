//! Judging a kernel's outputs against an f64 reference: relative error per output array (or
//! block), exact equality for integers, bitwise "untouched" for what the kernel must not write,
//! and plain conditions (coverage of the case, statistics). Every measure is printed.

/// Relative error allowed by issue 4's acceptance: `||out - ref|| / ||ref|| <= 1e-4`.
pub const TOLERANCE: f64 = 1e-4;

/// The measures of one case.
#[derive(Debug, Default)]
pub struct Report {
    pub case: String,
    lines: Vec<String>,
    pub failures: Vec<String>,
    /// The largest relative error measured, per label prefix up to ':' (the array or block).
    pub max_relative: Vec<(String, f64)>,
}

/// `||out - expected|| / ||expected||` in f64 (`||out||` when the reference is all zero);
/// non-finite outputs count as infinite error.
pub fn relative_error(out: &[f64], expected: &[f64]) -> f64 {
    assert_eq!(out.len(), expected.len(), "output and reference lengths");
    let mut diff = 0.0;
    let mut norm = 0.0;
    for (&o, &e) in out.iter().zip(expected) {
        if !o.is_finite() {
            return f64::INFINITY;
        }
        diff += (o - e) * (o - e);
        norm += e * e;
    }
    if norm > 0.0 {
        (diff / norm).sqrt()
    } else {
        diff.sqrt()
    }
}

impl Report {
    pub fn new(case: impl Into<String>) -> Report {
        Report {
            case: case.into(),
            ..Report::default()
        }
    }

    fn record_max(&mut self, label: &str, error: f64) {
        let key = label.split(':').next().unwrap_or(label).trim().to_owned();
        match self.max_relative.iter_mut().find(|(k, _)| *k == key) {
            Some((_, e)) => *e = e.max(error),
            None => self.max_relative.push((key, error)),
        }
    }

    /// Relative error of `out` against `expected`, at most [`TOLERANCE`].
    pub fn relative(&mut self, label: &str, out: &[f64], expected: &[f64]) -> f64 {
        self.relative_within(label, out, expected, TOLERANCE)
    }

    pub fn relative_within(
        &mut self,
        label: &str,
        out: &[f64],
        expected: &[f64],
        tolerance: f64,
    ) -> f64 {
        let error = relative_error(out, expected);
        let ok = error <= tolerance;
        self.lines.push(format!(
            "{label}: relative error {error:.2e} over {} values{}",
            out.len(),
            if ok { "" } else { "  <-- FAIL" }
        ));
        self.record_max(label, error);
        if !ok {
            let worst = out
                .iter()
                .zip(expected)
                .enumerate()
                .max_by(|a, b| {
                    let da = (a.1.0 - a.1.1).abs();
                    let db = (b.1.0 - b.1.1).abs();
                    da.is_nan().cmp(&db.is_nan()).then(da.total_cmp(&db))
                })
                .map(|(i, (o, e))| format!("worst at {i}: kernel {o} reference {e}"))
                .unwrap_or_default();
            self.failures.push(format!(
                "{label}: relative error {error:.3e} > {tolerance:.0e} ({worst})"
            ));
        }
        error
    }

    /// Integers that must be equal.
    pub fn exact(&mut self, label: &str, out: &[i32], expected: &[i32]) {
        let wrong: Vec<usize> = (0..out.len()).filter(|&i| out[i] != expected[i]).collect();
        self.lines.push(format!(
            "{label}: {} of {} values differ{}",
            wrong.len(),
            out.len(),
            if wrong.is_empty() { "" } else { "  <-- FAIL" }
        ));
        if let Some(&i) = wrong.first() {
            self.failures.push(format!(
                "{label}: {} of {} differ, first at {i}: kernel {} reference {}",
                wrong.len(),
                out.len(),
                out[i],
                expected[i]
            ));
        }
    }

    /// f32 values that must have exactly these bits (elements the kernel must not write, or
    /// must set to an exact value such as 0).
    pub fn bitwise_f32(&mut self, label: &str, out: &[f32], expected: &[f32]) {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits() as i32).collect::<Vec<_>>();
        self.exact(&format!("{label} (bitwise)"), &bits(out), &bits(expected));
    }

    /// A condition of the case or of the outputs.
    pub fn check(&mut self, ok: bool, what: impl Into<String>) {
        let what = what.into();
        self.lines
            .push(format!("{what}{}", if ok { "" } else { "  <-- FAIL" }));
        if !ok {
            self.failures.push(what);
        }
    }

    /// A line for the log only.
    pub fn note(&mut self, what: impl Into<String>) {
        self.lines.push(what.into());
    }

    pub fn print(&self) {
        println!("{}", self.case);
        for line in &self.lines {
            println!("    {line}");
        }
    }
}

/// f32 values widened.
pub fn wide(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x)).collect()
}

/// Prints every report and the largest relative error per label; panics listing the failures.
pub fn conclude(kernel: &str, reports: &[Report]) {
    let mut max: Vec<(String, f64)> = Vec::new();
    for r in reports {
        r.print();
        for (k, e) in &r.max_relative {
            match max.iter_mut().find(|(m, _)| m == k) {
                Some((_, m)) => *m = m.max(*e),
                None => max.push((k.clone(), *e)),
            }
        }
    }
    let overall = max.iter().map(|(_, e)| *e).fold(0.0, f64::max);
    println!(
        "{kernel}: max relative error {overall:.2e} over {} cases",
        reports.len()
    );
    for (k, e) in &max {
        println!("    {k}: {e:.2e}");
    }
    let failures: Vec<String> = reports
        .iter()
        .flat_map(|r| r.failures.iter().map(move |f| format!("{}: {f}", r.case)))
        .collect();
    assert!(
        failures.is_empty(),
        "{kernel}: {} failed checks:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
