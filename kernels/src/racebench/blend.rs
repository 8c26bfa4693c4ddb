//! Blending in the shader ("programmable blending"): `dst = src * a + dst * (1 - a)` on a
//! colour word in a storage buffer, as order-independent-transparency resolves and
//! custom blend modes do, without and with ordered pixel interlock (the use case of
//! fragment shader interlock).

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, InterlockMode, KernelInfo, Memory};

use super::run::{buffer, same_as};
use super::{case, Case, Fragments, Kind, Label, Meta, Spec, Violation, Words};

pub(super) fn cases() -> Vec<Box<dyn Case>> {
    vec![case::<BlendNoInterlock>(), case::<BlendInterlock>()]
}

const FAMILY: &str = "blend";

/// The fragment's colour and alpha (from its primitive).
fn source(f: &impl Fragment) -> (f32, f32) {
    let p = f.primitive_id() as f32;
    (0.2 + 0.15 * p, 0.5)
}

/// Blends over the pixel's colour word with a plain load and store.
async fn over(f: &impl Fragment, color: Buf<f32>) {
    let p = f.pixel_index();
    let (c, a) = source(f);
    let dst = f.load(color, p).await;
    f.store(color, p, c * a + dst * (1.0 - a)).await;
}

/// Shader blending with no interlock.
pub struct BlendNoInterlock {
    color: Buf<f32>,
}

impl FragmentKernel for BlendNoInterlock {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("blend-no-interlock")
    }
    async fn shade(&self, f: impl Fragment) {
        over(&f, self.color).await;
    }
}

impl Spec for BlendNoInterlock {
    type K = Self;
    const META: Meta = Meta {
        name: "blend-no-interlock",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("color")],
        kinds: &[Kind::LostUpdate, Kind::Race],
        pair: Some("blend-interlock"),
        limitation: None,
        what: "'over' blending in the shader by plain load and store, no interlock",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        BlendNoInterlock {
            color: buffer(dev, "color", pixels, 0.0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.color, "blended colour")
    }
}

/// Shader blending inside ordered pixel interlock (API order, as fixed-function blending).
pub struct BlendInterlock {
    color: Buf<f32>,
}

impl FragmentKernel for BlendInterlock {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("blend-interlock").with_interlock(InterlockMode::ORDERED)
    }
    async fn shade(&self, f: impl Fragment) {
        f.interlock_begin().await;
        over(&f, self.color).await;
        f.interlock_end().await;
    }
}

impl Spec for BlendInterlock {
    type K = Self;
    const META: Meta = Meta {
        name: "blend-interlock",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("blend-no-interlock"),
        limitation: None,
        what: "'over' blending in the shader inside ordered pixel interlock",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        BlendInterlock {
            color: buffer(dev, "color", pixels, 0.0),
        }
    }
    fn check(k: &Self, mem: &Memory, r: &Memory, _: &Fragments) -> Result<(), Violation> {
        same_as(mem, r, k.color, "blended colour")
    }
}
