//! Plans decoded ahead of their use, each on a thread of its own ([`super::PlanStore::prefetching`]).
//!
//! A 4096-world plan unpacks to about 70 MB of initial bytes, which takes a tenth of a second or
//! more of page faults and copies on one core; a run needs six plans, and used to decode two of
//! them twice (its checks, then its simulations). Decoded on threads while the command reads its
//! inputs and the GPU opens, each plan is read once, checked in place, and handed over to the
//! simulation that loads it.

use std::collections::HashMap;
use std::sync::Mutex;
use std::thread::JoinHandle;

use super::error::PlanError;
use super::model::Plan;

/// A plan being decoded on its thread, then its outcome.
struct Slot {
    decoding: Option<JoinHandle<Result<Plan, PlanError>>>,
    outcome: Option<Result<Plan, PlanError>>,
}

impl Slot {
    /// The outcome, waiting for the decoding thread if it is still at work.
    fn settle(&mut self) -> &Result<Plan, PlanError> {
        if let Some(handle) = self.decoding.take() {
            self.outcome = Some(handle.join().unwrap_or_else(|_| Err(panicked())));
        }
        self.outcome.get_or_insert_with(|| Err(panicked()))
    }

    fn into_outcome(mut self) -> Result<Plan, PlanError> {
        self.settle();
        self.outcome.unwrap_or_else(|| Err(panicked()))
    }
}

fn panicked() -> PlanError {
    PlanError::Asset("decoding the plan panicked on its thread (this is a bug)".to_owned())
}

/// Plans by name and world count, each decoded once on a thread of its own and handed out once.
#[derive(Default)]
pub(super) struct PrefetchedPlans {
    slots: Mutex<HashMap<(String, u32), Slot>>,
}

impl std::fmt::Debug for PrefetchedPlans {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let keys: Vec<(String, u32)> = self
            .slots
            .lock()
            .map(|s| s.keys().cloned().collect())
            .unwrap_or_default();
        f.debug_struct("PrefetchedPlans")
            .field("plans", &keys)
            .finish()
    }
}

impl PrefetchedPlans {
    /// Starts decoding `name` for `nworld` worlds with `decode` on a thread of its own.
    pub(super) fn start(
        &self,
        name: &str,
        nworld: u32,
        decode: impl FnOnce() -> Result<Plan, PlanError> + Send + 'static,
    ) {
        let handle = std::thread::spawn(decode);
        // A poisoned lock only means another thread panicked while holding it; the map is
        // still valid.
        let mut slots = self
            .slots
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        slots.entry((name.to_owned(), nworld)).or_insert(Slot {
            decoding: Some(handle),
            outcome: None,
        });
    }

    /// The prefetched plan, taken out (None: it was not prefetched, or is taken already).
    pub(super) fn take(&self, name: &str, nworld: u32) -> Option<Result<Plan, PlanError>> {
        let slot = self
            .slots
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .remove(&(name.to_owned(), nworld))?;
        Some(slot.into_outcome())
    }

    /// `inspect` on the prefetched plan, left in place for [`PrefetchedPlans::take`];
    /// `Err(inspect)` when it was not prefetched or is taken already. A plan that failed to
    /// decode is taken out with its error: a later request decodes it again and meets the same
    /// error.
    pub(super) fn inspect<T, F: FnOnce(&Plan) -> T>(
        &self,
        name: &str,
        nworld: u32,
        inspect: F,
    ) -> Result<Result<T, PlanError>, F> {
        let mut slots = self
            .slots
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let key = (name.to_owned(), nworld);
        let Some(slot) = slots.get_mut(&key) else {
            return Err(inspect);
        };
        if let Ok(plan) = slot.settle() {
            return Ok(Ok(inspect(plan)));
        }
        match slots.remove(&key) {
            Some(slot) => Ok(slot.into_outcome().map(|plan| inspect(&plan))),
            None => Err(inspect),
        }
    }
}
