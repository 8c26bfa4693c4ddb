//! The fuzz targets' logic, shared by the cargo-fuzz targets in `fuzz/` and the bounded smoke tests
//! of the normal test suite (`tests/fuzz_smoke.rs`), so that CI exercises every target.
//!
//! Each target is a plain function of the fuzzer's bytes (decoded with `arbitrary`) that
//! returns what it checked, or a [`Violation`] when it found a real bug; the libFuzzer
//! targets panic on a violation, which is how libFuzzer records a crash. Nothing here may
//! panic on any input: a panic is a bug of the code under test.
//!
//! - [`raster_watertight`]: arbitrary tilings (grids and fans of triangles that cover a region
//!   exactly, with arbitrary windings, sub-pixel positions, MSAA sample counts, tile sizes and
//!   near/far clipping) plus arbitrary other triangles through an arbitrary matrix (NaN,
//!   infinities, huge values), drawn through [`Device::draw`] with a counting kernel: within a
//!   tiling no sample is covered twice, no sample strictly inside the tiled region is missed,
//!   and no sample outside every triangle is covered; one triangle never covers a sample twice.
//! - [`kernel_oracle`]: an algorithm of the registry on a small random scene under the
//!   `scheduled` executor with an arbitrary schedule (`Policy::Bytes` of the remaining bytes),
//!   checked against the truth and against the algorithm's declared hazard class. One value of
//!   the selector byte picks the linked list with its planted bug instead
//!   ([`KernelOutcome::Planted`]), which the fuzzer is expected to find: a schedule under
//!   which the detector reports a torn record, or the in-pass reader follows the head to a
//!   node not written yet.
//! - [`obj_loader`]: [`parse_obj_bytes`] on arbitrary bytes; a mesh it accepts is valid and
//!   round-trips through OBJ text exactly.
//! - [`case_parser`]: [`case::parse`] on arbitrary bytes; a case it accepts re-serialises
//!   to a file that parses back equal; and an arbitrary case built from the bytes
//!   round-trips too.

//!
//! One file per target: [`raster`], [`kernel`], [`obj`], [`case_file`].

use std::fmt;

use arbitrary::{Arbitrary, Unstructured};

mod case_file;
mod kernel;
mod obj;
mod raster;

pub use case_file::{arbitrary_case, case_parser, case_round_trip, CaseOutcome};
pub use kernel::{
    kernel_oracle, kernel_oracle_input, oracle_algorithms, KernelInput, KernelOutcome,
};
pub use obj::{obj_loader, write_obj, ObjOutcome};
pub use raster::{
    raster_watertight, raster_watertight_input, Fan, Grid, RasterInput, RasterReport, Tiling,
};

/// A real bug found by a target: what was violated, with the details to reproduce it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Violation {
    pub target: &'static str,
    pub message: String,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.target, self.message)
    }
}

impl std::error::Error for Violation {}

fn violation(target: &'static str, message: impl Into<String>) -> Violation {
    Violation {
        target,
        message: message.into(),
    }
}

/// Decodes `data` as a `T`, taking all of it (as `fuzz_target!` does with a typed input).
/// `None` only if `arbitrary` cannot build a `T` at all (it never refuses for these types).
fn decode<'a, T: Arbitrary<'a>>(data: &'a [u8]) -> Option<T> {
    T::arbitrary_take_rest(Unstructured::new(data)).ok()
}
