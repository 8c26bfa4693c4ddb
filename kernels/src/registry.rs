//! Every algorithm, by name; the CLI, the differential test harness and the fuzzer take
//! them from here.
//!
//! **Adding an algorithm = one file and one registry line.** The file goes in its family's
//! folder (`kernels/src/<family>/<name>.rs`) and defines the algorithm
//! ([`Algorithm`]: info, passes, checks, result) and
//! `pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>>`, the variants it registers. The
//! line is the file's module name in its family's [`family!`] list (the family's
//! `mod.rs`), at the place the algorithm takes in the catalogue. Nothing else changes: the
//! family's `algorithms()` and [`algorithms`] below are generated from those lists. What
//! several algorithms of a family share lives in the family's shared modules (for the
//! k-buffers `slots`, `run` and `checks`; for the A-buffers `array`, `run` and `checks`),
//! declared as plain modules outside the list.
//!
//! A new family is a folder with such a list, and one line in [`algorithms`].

use crate::algo::Algorithm;
use crate::basic;

/// Declares the algorithm modules of a family, one per line, and the family's
/// `algorithms()`: every listed module's `algorithms()`, in the order listed (the
/// catalogue order). Each entry is a module (with its visibility and attributes, as a
/// `mod` item takes them) whose file defines `algorithms()`.
macro_rules! family {
    ($($(#[$attr:meta])* $vis:vis $name:ident),* $(,)?) => {
        $($(#[$attr])* $vis mod $name;)*

        /// The algorithms of this family, in catalogue order.
        pub fn algorithms() -> Vec<Box<dyn $crate::algo::Algorithm>> {
            let mut v: Vec<Box<dyn $crate::algo::Algorithm>> = Vec::new();
            $(v.extend($name::algorithms());)*
            v
        }
    };
}
pub(crate) use family;

/// Every algorithm, in catalogue order.
pub fn algorithms() -> Vec<Box<dyn Algorithm>> {
    let mut v: Vec<Box<dyn Algorithm>> = vec![
        Box::new(basic::Count),
        Box::new(basic::CountPlain),
        Box::new(basic::Opaque),
        Box::new(basic::Truth),
    ];
    v.extend(crate::abuffer::algorithms());
    v.extend(crate::kbuffer::algorithms());
    v.extend(crate::peeling::algorithms());
    v.extend(crate::merging::algorithms());
    v.extend(crate::bucket::algorithms());
    v
}

/// Algorithms that need an off-line preprocessing of a static mesh under assumptions
/// random scenes break (no intersecting or duplicate triangles, viewpoints outside a
/// bounding polyhedron): `fragrace presort` and `--algo` run them; the harnesses that
/// iterate [`algorithms`] over arbitrary scenes (fuzzers, the differential sweep) do not.
/// `tests/presorted.rs` holds them to their contract.
pub fn preprocessed() -> Vec<Box<dyn Algorithm>> {
    crate::presorted::algorithms()
}

/// The algorithm called `name` (of [`algorithms`] or [`preprocessed`]).
pub fn algorithm(name: &str) -> Option<Box<dyn Algorithm>> {
    algorithms()
        .into_iter()
        .chain(preprocessed())
        .find(|a| a.info().name == name)
}

/// All names.
pub fn names() -> Vec<&'static str> {
    algorithms().iter().map(|a| a.info().name).collect()
}
