//! A labelled race benchmark: small fragment kernels, each a synchronisation pattern that
//! multi-fragment rendering code really contains, each labelled `racy` or `race-free` with
//! the buffer words and the kind of hazard the detector should report. Racy and race-free
//! versions of one idea are paired wherever both exist.
//!
//! Every kernel runs on the fragments of a tiny scene ([`scene`]: a few overlapping
//! triangles over a few pixels, so that several fragments of each pixel meet) and has an
//! oracle ([`Spec::check`]) that compares what it left in memory with what it must leave:
//! `fragrace racebench` measures the hazard detector against the labels under every
//! scheduling policy, and the loom label checks (`kernels/tests/loom_racebench.rs`) show
//! that the labels are true: loom finds an oracle violation (or a hang) in every racy
//! kernel and none in any race-free one.
//!
//! Families, one file each: [`counters`] (counters, min/max, occupancy bits, histograms,
//! weighted sums), [`records`] (k-slot arrays, multi-word records, split keys, interlock
//! around part of a record), [`flags`] (check-then-act), [`locks`] (spinlocks),
//! [`lists`] (per-pixel linked lists), [`cas`] (compare-exchange loops, ABA),
//! [`buckets`] (bucket depth peeling), [`blend`] (blending in the shader).

pub mod blend;
pub mod buckets;
pub mod cas;
pub mod counters;
pub mod flags;
pub mod lists;
pub mod locks;
pub mod records;
mod run;
pub mod scene;

use fragrace_emu::{Device, ExecConfig, FragmentKernel, HazardKind, Memory};

pub use run::{Outcome, Report, Violation, MAX_STEPS};
pub use scene::Fragments;

/// What a kernel is, by its label.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Label {
    Racy,
    RaceFree,
}

impl Label {
    pub fn name(self) -> &'static str {
        match self {
            Label::Racy => "racy",
            Label::RaceFree => "race-free",
        }
    }
}

/// A kind of hazard a kernel is labelled with: the detector's three kinds, and a hang (a
/// watchdog fault: an invocation that never finishes, reported by the executor).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    LostUpdate,
    Race,
    Torn,
    Hang,
}

impl Kind {
    pub fn name(self) -> &'static str {
        match self {
            Kind::LostUpdate => "lost-update",
            Kind::Race => "race",
            Kind::Torn => "torn",
            Kind::Hang => "hang",
        }
    }
    pub fn of(k: HazardKind) -> Kind {
        match k {
            HazardKind::LostUpdate => Kind::LostUpdate,
            HazardKind::Race => Kind::Race,
            HazardKind::Torn => Kind::Torn,
        }
    }
}

/// Buffer words of a label: word `i` of `buffer` with `i % stride` in `slots` (every word
/// of the buffer when `slots` is empty).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Words {
    pub buffer: &'static str,
    pub stride: u32,
    pub slots: &'static [u32],
}

impl Words {
    /// Every word of `buffer`.
    pub const fn all(buffer: &'static str) -> Words {
        Words {
            buffer,
            stride: 1,
            slots: &[],
        }
    }
    /// Words `slots` of every `stride`-word record of `buffer`.
    pub const fn slots(buffer: &'static str, stride: u32, slots: &'static [u32]) -> Words {
        Words {
            buffer,
            stride,
            slots,
        }
    }
    pub fn contains(&self, buffer: &str, index: u32) -> bool {
        buffer == self.buffer
            && (self.slots.is_empty() || self.slots.contains(&(index % self.stride.max(1))))
    }
}

/// Why the detector cannot be right on a kernel, by design (docs/hazards.md): the
/// benchmark still measures it, and reports it apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Limitation {
    /// A racy kernel whose conflicting accesses are all atomic: an atomicity violation,
    /// not a data race, and not the one the detector knows (an atomic load, another's
    /// write, then a store of the loaded word: a lost update). The detector never reports
    /// atomic-vs-atomic; the oracle finds it.
    AtomicsOnly,
}

impl Limitation {
    pub fn name(self) -> &'static str {
        match self {
            Limitation::AtomicsOnly => "atomics-only",
        }
    }
}

/// A kernel's label and description.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Meta {
    pub name: &'static str,
    pub family: &'static str,
    pub label: Label,
    /// The words a report may name (empty for a hang: a watchdog fault names no word).
    pub words: &'static [Words],
    /// The kinds the detector should report (any of them counts).
    pub kinds: &'static [Kind],
    /// The kernel of the same idea with the other label.
    pub pair: Option<&'static str>,
    /// Known to be beyond the detector (see [`Limitation`]).
    pub limitation: Option<Limitation>,
    /// The pattern, in a sentence.
    pub what: &'static str,
}

/// One benchmark kernel: its label, how to set up its buffers, and its oracle.
pub trait Spec: Send + Sync + 'static {
    type K: FragmentKernel + Send + Sync + 'static;
    const META: Meta;
    /// Creates and initialises the kernel's buffers for `pixels` pixels.
    fn build(dev: &mut Device, pixels: u32) -> Self::K;
    /// Checks what `frags` left in `mem`. `reference` is the memory the `ordered` executor
    /// left (the same fragments one at a time in API order).
    fn check(
        k: &Self::K,
        mem: &Memory,
        reference: &Memory,
        frags: &Fragments,
    ) -> Result<(), Violation>;
}

/// A benchmark kernel behind a trait object (see [`Spec`]).
pub trait Case: Send + Sync {
    fn meta(&self) -> &'static Meta;
    /// One execution of `frags` under `exec` on fresh buffers.
    fn run(&self, frags: &Fragments, exec: &ExecConfig) -> Outcome;
    /// One execution with a thread per invocation (a loom thread under `--cfg loom`), each
    /// stopped after `max_steps` steps.
    fn run_threads(&self, frags: &Fragments, max_steps: u64) -> Outcome;
}

/// Every benchmark kernel, family by family.
pub fn cases() -> Vec<Box<dyn Case>> {
    let mut v = Vec::new();
    v.extend(counters::cases());
    v.extend(records::cases());
    v.extend(flags::cases());
    v.extend(locks::cases());
    v.extend(lists::cases());
    v.extend(cas::cases());
    v.extend(buckets::cases());
    v.extend(blend::cases());
    v
}

/// Boxes a [`Spec`] as a [`Case`].
pub(crate) fn case<S: Spec>() -> Box<dyn Case> {
    Box::new(run::Entry::<S>(std::marker::PhantomData))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_unique_pairs_exist_and_labels_are_well_formed() {
        let cs = cases();
        assert!(cs.len() >= 40, "{} kernels", cs.len());
        let names: Vec<&str> = cs.iter().map(|c| c.meta().name).collect();
        for (i, n) in names.iter().enumerate() {
            assert!(!names[..i].contains(n), "duplicate kernel name {n}");
        }
        for c in &cs {
            let m = c.meta();
            if let Some(p) = m.pair {
                let other = cs.iter().find(|o| o.meta().name == p);
                let other = other.unwrap_or_else(|| panic!("{}: pair {p} missing", m.name));
                assert_ne!(other.meta().label, m.label, "{} and {p}", m.name);
            }
            match m.label {
                Label::Racy => assert!(!m.kinds.is_empty(), "{}", m.name),
                Label::RaceFree => assert!(m.kinds.is_empty() && m.words.is_empty()),
            }
            if m.kinds.iter().any(|&k| k != Kind::Hang) {
                assert!(
                    !m.words.is_empty(),
                    "{}: a detector kind needs words",
                    m.name
                );
            }
        }
    }
}
