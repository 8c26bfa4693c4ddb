//! Fragment merging with the z-thickness model (Kim & Kye, "Z-Thickness Blending: Effective
//! Fragment Merging for Multi-Fragment Rendering", Computer Graphics Forum 40(7), 2021).
//!
//! One concept per module: `thickness` (the z-thickness model and its parameters, section
//! 3.1 and equation 9), `record` (the merged fragment and the over operator), `sfm` (smooth
//! merging, equations 1-5), `ofm` (order-independent merging, the mix operator of equations
//! 6-8), `algorithm1` (the resolve pass that merges N sorted fragments into M), and the
//! algorithms: `skb` (`skb-ofm`, `skb-ofm-unordered`), `dfb_sfm` (`dfb-sfm`), `kb_ofm`
//! (`kb-ofm`).
//!
//! Merging changes the fragment set on purpose, so these algorithms declare
//! [`Capacity::Image`](crate::Capacity::Image): the oracle compares their image with the
//! exact composite of the truth.

pub mod algorithm1;
pub mod ofm;
pub mod record;
pub mod sfm;
pub mod thickness;

crate::registry::family! {
    pub skb,
    dfb_sfm,
    kb_ofm,
}

pub use thickness::{DepthModel, MergeParamError, MergeParams, Thickness, ZModel};
