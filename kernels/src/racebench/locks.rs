//! Per-pixel spinlocks, as written where pixel interlock is missing (the spinlock k-buffer
//! of docs/hazards.md): compare-exchange 0 -> 1 to acquire, retried up to a cap, a count
//! of critical sections entered inside, a store of 0 to release. Variants: released by a
//! plain store, a plain critical section under a correct lock (ordered for the detector
//! by the release store and the acquiring compare-exchange), a coherent (atomic) critical
//! section, no cap, and a lock held across an early return.

use fragrace_emu::{Buf, Device, Fragment, FragmentKernel, KernelInfo, Memory};

use super::run::{buffer, read};
use super::{case, Case, Fragments, Kind, Label, Meta, Spec, Violation, Words};

pub(super) fn cases() -> Vec<Box<dyn Case>> {
    vec![
        case::<SpinPlainRelease>(),
        case::<SpinPlainSection>(),
        case::<SpinCoherent>(),
        case::<SpinUncapped>(),
        case::<SpinEarlyReturn>(),
    ]
}

const FAMILY: &str = "locks";
/// Lock attempts before a fragment gives up (and is counted).
pub const CAP: u32 = 16;

/// Takes the pixel's lock: compare-exchange 0 -> 1, at most `cap` attempts.
async fn acquire(f: &impl Fragment, lock: Buf<u32>, cap: u32) -> bool {
    let p = f.pixel_index();
    let mut attempts = 0u32;
    loop {
        if f.atomic_compare_exchange(lock, p, 0, 1).await.is_ok() {
            return true;
        }
        attempts = attempts.saturating_add(1);
        if attempts >= cap {
            return false;
        }
    }
}

/// The buffers of a lock kernel.
#[derive(Clone, Copy)]
pub struct LockBufs {
    lock: Buf<u32>,
    /// Critical sections entered.
    count: Buf<u32>,
    /// Fragments that gave up at the cap.
    gave_up: Buf<u32>,
}

impl LockBufs {
    fn new(dev: &mut Device, pixels: u32) -> LockBufs {
        LockBufs {
            lock: buffer(dev, "lock", pixels, 0),
            count: buffer(dev, "count", pixels, 0),
            gave_up: buffer(dev, "gave_up", pixels, 0),
        }
    }

    /// Every fragment entered or gave up, and every lock is free again.
    fn check(&self, mem: &Memory, fr: &Fragments) -> Result<(), Violation> {
        let (lock, count, gave_up) = (
            read(mem, self.lock),
            read(mem, self.count),
            read(mem, self.gave_up),
        );
        for p in 0..fr.pixels() {
            let i = p as usize;
            let n = fr.of_pixel(p).count() as u32;
            if count[i] + gave_up[i] != n {
                return Err(Violation::at(
                    format!(
                        "pixel {p}: {} sections + {} give-ups for {n} fragments",
                        count[i], gave_up[i]
                    ),
                    "count",
                    p,
                ));
            }
            if lock[i] != 0 {
                return Err(Violation::at(
                    format!("pixel {p}: lock left held"),
                    "lock",
                    p,
                ));
            }
        }
        Ok(())
    }
}

/// How the critical section and the release are written.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Style {
    /// Plain section, released by a plain store.
    PlainRelease,
    /// Plain section, atomic (release) store.
    PlainSection,
    /// Atomic loads and stores in the section, atomic release.
    Coherent,
}

/// Acquire (with `cap`), count the section, release; `early` primitives return while
/// holding the lock.
async fn locked(f: &impl Fragment, b: LockBufs, cap: u32, style: Style, early: Option<u32>) {
    let p = f.pixel_index();
    if !acquire(f, b.lock, cap).await {
        f.atomic_add(b.gave_up, p, 1).await;
        return;
    }
    if style == Style::Coherent {
        let n = f.atomic_load(b.count, p).await;
        f.atomic_store(b.count, p, n + 1).await;
    } else {
        let n = f.load(b.count, p).await;
        f.store(b.count, p, n + 1).await;
    }
    if early == Some(f.primitive_id()) {
        // As an alpha-tested fragment leaving early: the lock is never released.
        return;
    }
    if style == Style::PlainRelease {
        f.store(b.lock, p, 0).await;
    } else {
        f.atomic_store(b.lock, p, 0).await;
    }
}

macro_rules! lock_kernel {
    ($ty:ident, $cap:expr, $style:expr, $early:expr, $meta:expr) => {
        pub struct $ty(LockBufs);

        impl FragmentKernel for $ty {
            fn info(&self) -> KernelInfo {
                KernelInfo::new(<Self as Spec>::META.name)
            }
            async fn shade(&self, f: impl Fragment) {
                locked(&f, self.0, $cap, $style, $early).await;
            }
        }

        impl Spec for $ty {
            type K = Self;
            const META: Meta = $meta;
            fn build(dev: &mut Device, pixels: u32) -> Self {
                $ty(LockBufs::new(dev, pixels))
            }
            fn check(k: &Self, mem: &Memory, _: &Memory, fr: &Fragments) -> Result<(), Violation> {
                k.0.check(mem, fr)
            }
        }
    };
}

lock_kernel!(
    SpinPlainRelease,
    CAP,
    Style::PlainRelease,
    None,
    Meta {
        name: "spin-plain-release",
        family: FAMILY,
        label: Label::Racy,
        words: &[Words::all("lock"), Words::all("count")],
        kinds: &[Kind::Race, Kind::LostUpdate],
        pair: Some("spin-plain-section"),
        limitation: None,
        what: "spinlock released by a plain store: no release, the section's writes can be \
               seen late",
    }
);

lock_kernel!(
    SpinPlainSection,
    CAP,
    Style::PlainSection,
    None,
    Meta {
        name: "spin-plain-section",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("spin-plain-release"),
        limitation: None,
        what: "capped spinlock (acquire compare-exchange, release store) around a plain \
               critical section",
    }
);

lock_kernel!(
    SpinCoherent,
    CAP,
    Style::Coherent,
    None,
    Meta {
        name: "spin-coherent",
        family: FAMILY,
        label: Label::RaceFree,
        words: &[],
        kinds: &[],
        pair: Some("spin-uncapped"),
        limitation: None,
        what: "capped spinlock around a coherent (atomic load and store) critical section, \
               give-ups counted",
    }
);

lock_kernel!(
    SpinUncapped,
    u32::MAX,
    Style::Coherent,
    None,
    Meta {
        name: "spin-uncapped",
        family: FAMILY,
        label: Label::Racy,
        words: &[],
        kinds: &[Kind::Hang],
        pair: Some("spin-coherent"),
        limitation: None,
        what: "spinlock with no cap: a holder that is not scheduled starves its spinners",
    }
);

lock_kernel!(
    SpinEarlyReturn,
    u32::MAX,
    Style::Coherent,
    Some(1),
    Meta {
        name: "spin-early-return",
        family: FAMILY,
        label: Label::Racy,
        words: &[],
        kinds: &[Kind::Hang],
        pair: Some("spin-coherent"),
        limitation: None,
        what: "spinlock held across an early return (primitive 1 leaves without releasing)",
    }
);
