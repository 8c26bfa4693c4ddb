//! Check-then-act on a per-pixel flag: the first fragment to arrive claims the pixel (as a
//! first-hit or "visited" mark). Tested by plain load then plain store, by an atomic load
//! then an atomic store (atomic, yet still two steps), and by one compare-exchange.

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, KernelInfo, Memory};

use super::run::{buffer, read};
use super::{case, Case, Fragments, Kind, Label, Meta, Spec, Violation, Words};

pub(super) fn cases() -> Vec<Box<dyn Case>> {
    vec![
        case::<FlagPlain>(),
        case::<FlagAtomicLoadStore>(),
        case::<FlagCas>(),
    ]
}

const FAMILY: &str = "flags";

/// The pixel's flag and how many fragments claimed it (an atomic counter, so that the
/// oracle sees every claim).
fn flag_buffers(dev: &mut Device, pixels: u32) -> (Buf<u32>, Buf<u32>) {
    (
        buffer(dev, "flag", pixels, 0),
        buffer(dev, "claims", pixels, 0),
    )
}

/// Exactly one fragment of each covered pixel must have claimed it.
fn one_claim(claims: Buf<u32>, mem: &Memory, fr: &Fragments) -> Result<(), Violation> {
    let c = read(mem, claims);
    for p in 0..fr.pixels() {
        let covered = fr.of_pixel(p).next().is_some() as u32;
        if c[p as usize] != covered {
            return Err(Violation::at(
                format!("pixel {p} claimed {} times", c[p as usize]),
                "flag",
                p,
            ));
        }
    }
    Ok(())
}

/// `if flag == 0 { flag = 1; claim }` by plain load and store.
pub struct FlagPlain {
    flag: Buf<u32>,
    claims: Buf<u32>,
}

impl FragmentKernel for FlagPlain {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("flag-check-then-act")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        if f.load(self.flag, p).await == 0 {
            f.store(self.flag, p, 1).await;
            f.atomic_add(self.claims, p, 1).await;
        }
    }
}

impl Spec for FlagPlain {
    type K = Self;
    const META: Meta = Meta {
        name: "flag-check-then-act",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("flag")],
        kinds: &[Kind::Race, Kind::LostUpdate],
        pair: Some("flag-cas"),
        limitation: None,
        what: "first-arrival flag tested by plain load, then set by plain store",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        let (flag, claims) = flag_buffers(dev, pixels);
        FlagPlain { flag, claims }
    }
    fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
        one_claim(k.claims, mem, fr)
    }
}

/// The same check-then-act with an atomic load and an atomic store: each access is
/// atomic, the pair is not.
pub struct FlagAtomicLoadStore {
    flag: Buf<u32>,
    claims: Buf<u32>,
}

impl FragmentKernel for FlagAtomicLoadStore {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("flag-atomic-load-store")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        if f.atomic_load(self.flag, p).await == 0 {
            f.atomic_store(self.flag, p, 1).await;
            f.atomic_add(self.claims, p, 1).await;
        }
    }
}

impl Spec for FlagAtomicLoadStore {
    type K = Self;
    const META: Meta = Meta {
        name: "flag-atomic-load-store",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("flag")],
        kinds: &[Kind::LostUpdate],
        pair: Some("flag-cas"),
        limitation: None,
        what: "first-arrival flag tested by atomic load, then set by atomic store",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        let (flag, claims) = flag_buffers(dev, pixels);
        FlagAtomicLoadStore { flag, claims }
    }
    fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
        one_claim(k.claims, mem, fr)
    }
}

/// The flag claimed by one compare-exchange 0 -> 1.
pub struct FlagCas {
    flag: Buf<u32>,
    claims: Buf<u32>,
}

impl FragmentKernel for FlagCas {
    fn info(&self) -> KernelInfo {
        KernelInfo::new("flag-cas")
    }
    async fn shade(&self, f: impl Fragment) {
        let p = f.pixel_index();
        if f.atomic_compare_exchange(self.flag, p, 0, 1).await.is_ok() {
            f.atomic_add(self.claims, p, 1).await;
        }
    }
}

impl Spec for FlagCas {
    type K = Self;
    const META: Meta = Meta {
        name: "flag-cas",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("flag-check-then-act"),
        limitation: None,
        what: "first-arrival flag claimed by one compare-exchange",
    };
    fn build(dev: &mut Device, pixels: u32) -> Self {
        let (flag, claims) = flag_buffers(dev, pixels);
        FlagCas { flag, claims }
    }
    fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
        one_claim(k.claims, mem, fr)
    }
}
