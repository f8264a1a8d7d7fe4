//! Facts computed from a value's contents once and kept with the value: an octree's clearance
//! bricks, whether a medium absorbs anywhere. Every node reading the same value (the same
//! result held by the engine's cache) shares them, so an edit that re-runs only the nodes
//! downstream of a volume does not rebuild them; a changed volume is a new value and starts
//! without them.

use std::any::Any;
use std::sync::{Arc, Mutex};

/// The facts derived so far, by name. A copy starts empty (its contents may then change), two
/// values compare equal whatever they hold, and it is never encoded.
#[derive(Default)]
pub struct Derived(Mutex<Vec<(&'static str, Arc<dyn Any + Send + Sync>)>>);

impl Derived {
    /// The fact `name`, made by `make` the first time. `make` runs outside the lock: nodes
    /// asking at once may both make it (the same value, the first kept), where holding the
    /// lock could block a rayon worker that the maker's own parallel loop is waiting for.
    pub fn get<T: Any + Send + Sync>(&self, name: &'static str, make: impl FnOnce() -> T) -> Arc<T> {
        let found = |memo: &Vec<(&'static str, Arc<dyn Any + Send + Sync>)>| {
            memo.iter().find(|(n, _)| *n == name).and_then(|(_, v)| v.clone().downcast::<T>().ok())
        };
        if let Some(t) = found(&self.0.lock().unwrap_or_else(|e| e.into_inner())) {
            return t;
        }
        let made = Arc::new(make());
        let mut memo = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(t) = found(&memo) {
            return t;
        }
        memo.push((name, made.clone()));
        made
    }
}

impl Clone for Derived {
    fn clone(&self) -> Self {
        Derived::default()
    }
}

impl PartialEq for Derived {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl std::fmt::Debug for Derived {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let names: Vec<&str> = self.0.lock().map(|m| m.iter().map(|(n, _)| *n).collect()).unwrap_or_default();
        write!(f, "Derived({names:?})")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn a_fact_is_made_once_and_a_copy_starts_without_it() {
        let d = Derived::default();
        let made = AtomicUsize::new(0);
        let make = || {
            made.fetch_add(1, Ordering::Relaxed);
            42u32
        };
        assert_eq!(*d.get("answer", make), 42);
        assert_eq!(*d.get("answer", || 7u32), 42, "kept from the first time");
        assert_eq!(made.load(Ordering::Relaxed), 1);
        assert_eq!(*d.clone().get("answer", || 7u32), 7, "a copy makes its own");
        assert_eq!(*d.get("other", || true), true);
        assert_eq!(d, Derived::default());
        assert!(format!("{d:?}").contains("answer"));
    }
}
