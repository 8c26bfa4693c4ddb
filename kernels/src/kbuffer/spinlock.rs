//! (being written)

use crate::algo::Algorithm;

pub(super) fn algorithms() -> Vec<Box<dyn Algorithm>> {
    Vec::new()
}
