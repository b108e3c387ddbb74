//! MuJoCo Warp's per-world overflow flags (`d.overflow`, its `OverflowType` bits). The plans are
//! captured without the kernels' prints for the solver's iteration limits (kernels_py/physics.py),
//! so the flags are how a run learns of them; they stay set until a world is reset by MuJoCo
//! Warp, which our resets are not, so they count every world that overflowed since the plans
//! were loaded.

use super::simulation::{Simulation, SimulationError};

/// Constraint rows beyond `njmax` were dropped.
const NEFC: i32 = 1 << 0;
/// The sparse Jacobian's non-zeros overflowed.
const NJMAX_NNZ: i32 = 1 << 1;
/// Broadphase pairs or contacts beyond `nconmax` were dropped.
const BROADPHASE: i32 = 1 << 2;
const NARROWPHASE: i32 = 1 << 3;
/// The Newton solver stopped at `iterations` before converging.
const ITERATIONS: i32 = 1 << 9;
/// A linesearch stopped at `ls_iterations`.
const LS_ITERATIONS: i32 = 1 << 10;

/// How many worlds have each kind of overflow flag set.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PhysicsOverflow {
    pub worlds: usize,
    /// Constraint rows or Jacobian non-zeros dropped (`njmax`).
    pub constraint_rows: usize,
    /// Collision pairs or contacts dropped (`nconmax`).
    pub contacts: usize,
    /// The solver stopped at its iteration limit.
    pub solver_iterations: usize,
    /// A linesearch stopped at its iteration limit.
    pub linesearch_iterations: usize,
}

impl PhysicsOverflow {
    /// Counts the flags of `d.overflow` (one i32 per world).
    pub fn from_flags(flags: &[i32]) -> PhysicsOverflow {
        let count = |mask: i32| flags.iter().filter(|&&f| f & mask != 0).count();
        PhysicsOverflow {
            worlds: flags.len(),
            constraint_rows: count(NEFC | NJMAX_NNZ),
            contacts: count(BROADPHASE | NARROWPHASE),
            solver_iterations: count(ITERATIONS),
            linesearch_iterations: count(LS_ITERATIONS),
        }
    }

    /// Reads a simulation's flags (waits for its stream).
    pub fn read(sim: &Simulation) -> Result<PhysicsOverflow, SimulationError> {
        Ok(PhysicsOverflow::from_flags(
            &sim.buffer::<i32>("d.overflow")?.read()?,
        ))
    }

    /// One line for a person, or `None` when no world overflowed. Dropped contacts or
    /// constraint rows change the physics and say which capacity to raise; iteration limits are
    /// routine with few Newton iterations and are reported as counts.
    pub fn describe(&self) -> Option<String> {
        let mut parts = Vec::new();
        if self.constraint_rows > 0 {
            parts.push(format!(
                "constraint rows dropped in {} (raise njmax in the physics config and capture the plans again)",
                self.constraint_rows
            ));
        }
        if self.contacts > 0 {
            parts.push(format!(
                "contacts dropped in {} (raise nconmax in the physics config and capture the plans again)",
                self.contacts
            ));
        }
        if self.solver_iterations > 0 {
            parts.push(format!(
                "solver iteration limit reached in {}",
                self.solver_iterations
            ));
        }
        if self.linesearch_iterations > 0 {
            parts.push(format!(
                "linesearch iteration limit reached in {}",
                self.linesearch_iterations
            ));
        }
        if parts.is_empty() {
            return None;
        }
        Some(format!(
            "physics: {} of {} worlds since start",
            parts.join(", "),
            self.worlds
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_are_counted_by_kind() {
        let flags = [
            0,
            ITERATIONS,
            ITERATIONS | LS_ITERATIONS,
            NEFC,
            NARROWPHASE | ITERATIONS,
        ];
        let overflow = PhysicsOverflow::from_flags(&flags);
        assert_eq!(
            overflow,
            PhysicsOverflow {
                worlds: 5,
                constraint_rows: 1,
                contacts: 1,
                solver_iterations: 3,
                linesearch_iterations: 1,
            }
        );
        let line = overflow.describe().unwrap();
        assert!(
            line.contains("constraint rows dropped in 1 (raise njmax"),
            "{line}"
        );
        assert!(
            line.contains("contacts dropped in 1 (raise nconmax"),
            "{line}"
        );
        assert!(
            line.contains("solver iteration limit reached in 3"),
            "{line}"
        );
        assert!(line.ends_with("of 5 worlds since start"), "{line}");
        assert_eq!(PhysicsOverflow::from_flags(&[0, 0]).describe(), None);
    }
}
