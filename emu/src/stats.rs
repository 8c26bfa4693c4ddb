//! Instrumentation: what a pass did (fragments, operations by kind, interlock waits,
//! contention per address). This module knows nothing of algorithms.

use std::collections::HashMap;

use crate::memory::{Addr, OpKind};
use crate::sync::{AtomicU32, Ordering};

/// Counters of one pass (or a sum of passes).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stats {
    /// Geometry passes and full-screen passes run.
    pub geometry_passes: u32,
    pub fullscreen_passes: u32,
    /// Fragments out of the rasterizer (pixels with at least one covered sample).
    pub fragments_generated: u64,
    /// Fragments killed by the early depth/stencil test before shading.
    pub early_culled: u64,
    /// Kernel invocations run.
    pub shaded: u64,
    /// Full-screen invocations not run: their pixel no geometry pass reached, and the
    /// kernel declared its output there (`KernelInfo::with_untouched_output`).
    #[serde(default)]
    pub skipped: u64,
    /// Invocations that called `discard`.
    pub discarded: u64,
    /// Fragments killed by the late depth/stencil test.
    pub late_culled: u64,
    /// Samples that passed every test and were written (occlusion query).
    pub samples_passed: u64,
    /// Invocations ended by a fault.
    pub faulted: u64,
    /// Memory operations by kind.
    pub ops: OpCounts,
    /// Steps (memory accesses, interlock entries and exits, yields).
    pub steps: u64,
    /// Times an invocation found the interlock taken (direct mode: polls that waited).
    pub interlock_waits: u64,
    /// Most steps taken by one invocation.
    pub max_steps_per_invocation: u64,
    /// Hottest addresses (by accesses), with their peak number of concurrent accessors.
    pub hotspots: Vec<Hotspot>,
    /// Triangles dropped by the rasterizer for non-finite coordinates.
    pub rejected_triangles: u64,
}

/// One contended address.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Hotspot {
    pub buffer: String,
    pub index: u32,
    pub accesses: u64,
    /// Most invocations accessing it at the same moment (parallel: inside the same
    /// operation; scheduled: in flight and having touched it).
    pub peak_concurrent: u32,
}

/// Memory operations by kind, indexed like [`OpKind::ALL`]; serialised as a map from
/// [`OpKind::name`] to count (kinds never used are left out).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OpCounts(pub [u64; 13]);

impl OpCounts {
    /// The count of the kind named `name` (e.g. `"add"`), `None` if it was never used.
    pub fn get(&self, name: &str) -> Option<&u64> {
        OpKind::ALL
            .iter()
            .position(|k| k.name() == name)
            .map(|i| &self.0[i])
            .filter(|&&n| n > 0)
    }
    pub fn of(&self, kind: OpKind) -> u64 {
        self.0[kind as usize]
    }
    /// (name, count) of the kinds used.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        OpKind::ALL
            .iter()
            .zip(self.0.iter())
            .filter(|(_, &n)| n > 0)
            .map(|(k, &n)| (k.name(), n))
    }
}

impl serde::Serialize for OpCounts {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(None)?;
        for (k, v) in self.iter() {
            m.serialize_entry(k, &v)?;
        }
        m.end()
    }
}

impl<'de> serde::Deserialize<'de> for OpCounts {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let m: HashMap<String, u64> = HashMap::deserialize(d)?;
        let mut c = OpCounts::default();
        for (k, v) in m {
            if let Some(i) = OpKind::ALL.iter().position(|o| o.name() == k) {
                c.0[i] = v;
            }
        }
        Ok(c)
    }
}

impl Stats {
    pub(crate) fn add_ops(&mut self, ops: &[u32; 13]) {
        for (a, &n) in self.ops.0.iter_mut().zip(ops) {
            *a += n as u64;
        }
    }
    /// Total atomic operations (everything but plain loads and stores).
    pub fn atomics(&self) -> u64 {
        self.ops
            .iter()
            .filter(|(k, _)| *k != "load" && *k != "store")
            .map(|(_, v)| v)
            .sum()
    }
    /// Adds another pass's counters.
    pub fn merge(&mut self, o: &Stats) {
        self.geometry_passes += o.geometry_passes;
        self.fullscreen_passes += o.fullscreen_passes;
        self.fragments_generated += o.fragments_generated;
        self.early_culled += o.early_culled;
        self.shaded += o.shaded;
        self.skipped += o.skipped;
        self.discarded += o.discarded;
        self.late_culled += o.late_culled;
        self.samples_passed += o.samples_passed;
        self.faulted += o.faulted;
        for (a, b) in self.ops.0.iter_mut().zip(o.ops.0.iter()) {
            *a += b;
        }
        self.steps += o.steps;
        self.interlock_waits += o.interlock_waits;
        self.max_steps_per_invocation = self
            .max_steps_per_invocation
            .max(o.max_steps_per_invocation);
        self.rejected_triangles += o.rejected_triangles;
        if o.hotspots.is_empty() {
            return;
        }
        for h in &o.hotspots {
            match self
                .hotspots
                .iter_mut()
                .find(|x| x.buffer == h.buffer && x.index == h.index)
            {
                Some(x) => {
                    x.accesses += h.accesses;
                    x.peak_concurrent = x.peak_concurrent.max(h.peak_concurrent);
                }
                None => self.hotspots.push(h.clone()),
            }
        }
        self.hotspots
            .sort_by(|a, b| b.accesses.cmp(&a.accesses).then(a.index.cmp(&b.index)));
        self.hotspots.truncate(HOTSPOTS);
    }
}

/// How many hotspots a report keeps.
pub const HOTSPOTS: usize = 8;

/// Per-word access counters and in-flight accessor counts, for the parallel executor's
/// contention figures (three atomics per access, so only when asked for).
pub struct ContentionTable {
    /// First slot of each buffer's range in the tables, by buffer id.
    bases: Vec<usize>,
    lens: Vec<usize>,
    accesses: Box<[AtomicU32]>,
    inflight: Box<[AtomicU32]>,
    peak: Box<[AtomicU32]>,
}

/// Marks one access as in flight until dropped.
pub struct ContentionGuard<'a> {
    slot: &'a AtomicU32,
}

impl Drop for ContentionGuard<'_> {
    fn drop(&mut self) {
        self.slot.fetch_sub(1, Ordering::Relaxed);
    }
}

impl ContentionTable {
    /// A table for buffers of the given word counts (by buffer id).
    pub fn new(buffer_words: &[u32]) -> ContentionTable {
        let mut bases = Vec::with_capacity(buffer_words.len());
        let mut n = 0usize;
        for &w in buffer_words {
            bases.push(n);
            n += w as usize;
        }
        let mk = || {
            (0..n)
                .map(|_| AtomicU32::new(0))
                .collect::<Box<[AtomicU32]>>()
        };
        let lens = buffer_words.iter().map(|&w| w as usize).collect();
        ContentionTable {
            bases,
            lens,
            accesses: mk(),
            inflight: mk(),
            peak: mk(),
        }
    }

    fn slot(&self, addr: Addr) -> usize {
        self.bases[addr.buffer() as usize] + addr.index() as usize
    }

    pub fn enter(&self, addr: Addr) -> ContentionGuard<'_> {
        let i = self.slot(addr);
        self.accesses[i].fetch_add(1, Ordering::Relaxed);
        let now = self.inflight[i].fetch_add(1, Ordering::Relaxed) + 1;
        self.peak[i].fetch_max(now, Ordering::Relaxed);
        ContentionGuard {
            slot: &self.inflight[i],
        }
    }

    /// The hottest addresses, named.
    pub fn hotspots(&self, name: impl Fn(u32) -> String) -> Vec<Hotspot> {
        let mut hot: Vec<(u64, usize)> = self
            .accesses
            .iter()
            .enumerate()
            .map(|(i, a)| (a.load(Ordering::Relaxed) as u64, i))
            .filter(|&(a, _)| a > 0)
            .collect();
        hot.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        hot.truncate(HOTSPOTS);
        hot.into_iter()
            .map(|(accesses, i)| {
                let buffer = (0..self.bases.len())
                    .find(|&b| self.bases[b] <= i && i < self.bases[b] + self.lens[b])
                    .unwrap_or(0);
                Hotspot {
                    buffer: name(buffer as u32),
                    index: (i - self.bases[buffer]) as u32,
                    accesses,
                    peak_concurrent: self.peak[i].load(Ordering::Relaxed),
                }
            })
            .collect()
    }
}
