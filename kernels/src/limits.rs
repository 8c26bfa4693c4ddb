//! What [`Params`] may hold, checked before a run ([`Params::validate`]). Values out of
//! range are refused, never clamped. An algorithm may narrow a range further when it runs
//! (the k-buffers keep at most 64 slots per pixel).

use crate::algo::Params;

/// Largest k any algorithm accepts (the depth-peeling layer cap,
/// [`crate::peeling::MAX_LAYERS`]).
pub const MAX_K: u32 = crate::peeling::MAX_LAYERS;

/// A parameter out of its range.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ParamsError {
    #[error("{name} = {value} is out of range: it must be from {min} to {max}")]
    OutOfRange {
        /// The parameter, as the command line and case files name it.
        name: &'static str,
        value: u64,
        min: u64,
        max: u64,
    },
    #[error("{name} = {value} is out of range: it must be {range}")]
    OutOfRangeF {
        name: &'static str,
        value: f32,
        range: &'static str,
    },
}

fn range(name: &'static str, value: u32, min: u32, max: u32) -> Result<(), ParamsError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(ParamsError::OutOfRange {
            name,
            value: value.into(),
            min: min.into(),
            max: max.into(),
        })
    }
}

impl Params {
    /// Checks every parameter against its range.
    pub fn validate(&self) -> Result<(), ParamsError> {
        range("k (--k)", self.k, 1, MAX_K)?;
        range("spin_cap (--spin-cap)", self.spin_cap, 1, u32::MAX)?;
        range("buckets", self.buckets, 1, u32::MAX)?;
        range("fab_capacity", self.fab_capacity, 1, u32::MAX)?;
        if !(0.0..=1.0).contains(&self.alpha) {
            return Err(ParamsError::OutOfRangeF {
                name: "alpha (--alpha)",
                value: self.alpha,
                range: "from 0 to 1",
            });
        }
        if let Some(p) = self.pool_per_pixel {
            if !(p.is_finite() && p > 0.0) {
                return Err(ParamsError::OutOfRangeF {
                    name: "pool_per_pixel",
                    value: p,
                    range: "positive and finite",
                });
            }
        }
        if let Some(c) = self.background.iter().find(|c| !c.is_finite()) {
            return Err(ParamsError::OutOfRangeF {
                name: "background",
                value: *c,
                range: "finite",
            });
        }
        Ok(())
    }
}
