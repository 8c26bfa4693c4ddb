//! Running a benchmark kernel once and reading out what was reported and what its oracle
//! says; helpers for the oracles.

use std::marker::PhantomData;

use fragrace_emu::exec::run_on_threads;
use fragrace_emu::sync::Arc;
use fragrace_emu::{Buf, Device, ExecConfig, FaultKind, Memory, Word};

use super::{Case, Fragments, Kind, Meta, Spec};

/// Watchdog of the benchmark's invocations: far above the steps any race-free kernel here
/// takes (tens), low enough that a hang costs little.
pub const MAX_STEPS: u64 = 4096;

/// One thing reported in an execution: a hazard on a word, or a hang (no word).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
pub struct Report {
    pub kind: Kind,
    /// (buffer, index); `None` for a hang.
    pub word: Option<(String, u32)>,
}

/// An oracle's finding: what is wrong and where.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Violation {
    pub what: String,
    /// The words found wrong (buffer, index), when the oracle can say.
    pub words: Vec<(String, u32)>,
}

impl Violation {
    pub fn new(what: impl Into<String>) -> Violation {
        Violation {
            what: what.into(),
            words: Vec::new(),
        }
    }
    pub fn at(what: impl Into<String>, buffer: &str, index: u32) -> Violation {
        Violation {
            what: what.into(),
            words: vec![(buffer.to_string(), index)],
        }
    }
}

/// What one execution produced.
#[derive(Clone, Debug, Default)]
pub struct Outcome {
    /// Detector hazards and hangs, deduplicated (kind, word).
    pub reports: Vec<Report>,
    /// The oracle's verdict.
    pub violation: Option<Violation>,
    /// Faults other than hangs (out-of-bounds, panic, misuse): a bug of the benchmark.
    pub faults: Vec<String>,
}

impl Outcome {
    fn fault(&mut self, kind: &FaultKind) {
        match kind {
            FaultKind::Watchdog { .. }
            | FaultKind::Deadlock { .. }
            | FaultKind::SimtDeadlock { .. } => {
                let r = Report {
                    kind: Kind::Hang,
                    word: None,
                };
                if !self.reports.contains(&r) {
                    self.reports.push(r);
                }
            }
            other => self.faults.push(other.to_string()),
        }
    }
}

pub(super) struct Entry<S>(pub PhantomData<S>);

/// A fresh device with `S`'s buffers, after running `frags` one at a time in API order.
fn reference<S: Spec>(frags: &Fragments) -> Device {
    let mut dev = Device::new();
    let k = S::build(&mut dev, frags.pixels());
    let exec = ExecConfig {
        max_steps: MAX_STEPS,
        max_waits: MAX_STEPS,
        ..ExecConfig::ordered()
    };
    dev.invocations(frags.width, frags.height, &frags.inputs, &k, &exec);
    dev
}

impl<S: Spec> Case for Entry<S> {
    fn meta(&self) -> &'static Meta {
        &S::META
    }

    fn run(&self, frags: &Fragments, exec: &ExecConfig) -> Outcome {
        let mut dev = Device::new();
        let k = S::build(&mut dev, frags.pixels());
        let pass = dev.invocations(frags.width, frags.height, &frags.inputs, &k, exec);
        let mut out = Outcome::default();
        for h in &pass.hazard_list {
            let r = Report {
                kind: Kind::of(h.kind),
                word: Some((h.buffer.clone(), h.index)),
            };
            if !out.reports.contains(&r) {
                out.reports.push(r);
            }
        }
        for f in &pass.faults {
            out.fault(&f.kind);
        }
        let reference = reference::<S>(frags);
        out.violation = S::check(&k, &dev.memory, &reference.memory, frags).err();
        out
    }

    fn run_threads(&self, frags: &Fragments, max_steps: u64) -> Outcome {
        let mut dev = Device::new();
        let k = S::build(&mut dev, frags.pixels());
        let memory = Arc::new(dev.memory);
        let outcomes = run_on_threads(
            Arc::new(k),
            memory.clone(),
            frags.inputs.clone(),
            frags.width,
            frags.height,
            max_steps,
        );
        let mem = Arc::try_unwrap(memory)
            .ok()
            .expect("every invocation thread has been joined");
        let mut out = Outcome::default();
        for o in &outcomes {
            if let Some(f) = &o.fault {
                out.fault(f);
            }
        }
        // The kernel's handles are copies: build them again on a device laid out alike.
        let mut dev2 = Device::new();
        let k = S::build(&mut dev2, frags.pixels());
        let reference = reference::<S>(frags);
        out.violation = S::check(&k, &mem, &reference.memory, frags).err();
        out
    }
}

/// The words of `buf` whose values in `mem` and `reference` differ, as a violation.
pub fn same_as<T: Word + PartialEq>(
    mem: &Memory,
    reference: &Memory,
    buf: Buf<T>,
    what: &str,
) -> Result<(), Violation> {
    let (a, b) = (read(mem, buf), read(reference, buf));
    let words: Vec<(String, u32)> = (0..a.len())
        .filter(|&i| a[i] != b[i])
        .map(|i| (mem.buffer_name(buf.id()).to_string(), i as u32))
        .collect();
    if words.is_empty() {
        return Ok(());
    }
    Err(Violation {
        what: format!(
            "{what}: {} word(s) differ from the ordered run",
            words.len()
        ),
        words,
    })
}

/// The contents of `buf` (the benchmark's buffers always exist: an error is a bug here).
pub fn read<T: Word>(mem: &Memory, buf: Buf<T>) -> Vec<T> {
    mem.read(buf).expect("a benchmark buffer")
}

/// Creates a buffer filled with `value`.
pub fn buffer<T: Word>(dev: &mut Device, name: &str, len: u32, value: T) -> Buf<T> {
    let b = dev.buffer::<T>(name, len as u64).expect("a small buffer");
    dev.memory.fill(b, value).expect("a small buffer");
    b
}
