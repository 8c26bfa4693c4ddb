//! Happens-before through atomics, for the hazard detector: vector clocks over the
//! detector's lanes (the executor's slots, one in-flight invocation each), as the
//! emulator's atomics behave. Kernel atomics run with acquire-release ordering
//! (`Frag::perform_counted`): an atomic load or a failed compare-exchange acquires, an
//! atomic store releases, a read-modify-write does both (and continues the release sequence
//! of the value it replaces). A plain store to a word ends its release sequence: whoever
//! reads that value synchronises with nobody.
//!
//! Happens-before is the transitive closure of
//! - program order within an invocation,
//! - release -> acquire: an atomic write, then an atomic read of the value it wrote,
//! - finish -> start: an invocation that finished before another started (the detector's
//!   rule since before there were clocks: lifetimes that do not overlap are ordered).
//!
//! Costs are bounded by the lanes, not by the pass: a clock has one entry per lane in use
//! (at most [`MAX_CLOCK_LANES`]); each lane holds the clock of its invocation, each atomic
//! word written in the pass one clock (the one its last release published). An acquire
//! joins two clocks, a release copies one, a start copies and a finish joins one.
//!
//! Epochs: lane `u`'s entry counts that lane's releases. They are never reset within a
//! pass, so an invocation started in a lane begins past every epoch its predecessors in the
//! lane used; knowing lane `u` up to epoch `e` means knowing every access made in lane `u`
//! at an epoch up to `e`, by whichever invocation (the earlier ones finished before the
//! later started: ordered by the third rule).

/// Lanes whose invocations get clocks. Invocations in lanes past it (windows over 256)
/// are ordered by interlock and lifetimes only, as before the clocks: a clock costs 4
/// bytes per lane, for every lane and every atomic word written in the pass.
pub const MAX_CLOCK_LANES: usize = 256;

/// No clock (an atomic word that was never released to); a word's clock is otherwise
/// `1 + ` its index among the pass's word clocks.
pub(super) const NO_CLOCK: u32 = 0;

/// The epoch of an access made outside the clocks (no invocation's clock ever reaches it).
pub(super) const UNTRACKED: u32 = u32::MAX;

/// The lane of an access made outside the clocks.
pub(super) const NO_LANE: u16 = u16::MAX;

/// Copies clock `src` into `dst` (of one length, a multiple of 4, as every clock's: the
/// stride is a power of two from 4 up). In chunks of 4, a copy is a vector move or two,
/// where one of a length known only at run time was a call to `memcpy`.
#[inline(always)]
fn copy(dst: &mut [u32], src: &[u32]) {
    debug_assert!(dst.len() == src.len() && dst.len().is_multiple_of(4));
    let (d, _) = dst.as_chunks_mut::<4>();
    let (s, _) = src.as_chunks::<4>();
    for (d, s) in d.iter_mut().zip(s) {
        *d = *s;
    }
}

/// Joins clock `src` into `dst` (entrywise maximum; lengths as in [`copy`]).
#[inline(always)]
fn join(dst: &mut [u32], src: &[u32]) {
    debug_assert!(dst.len() == src.len() && dst.len().is_multiple_of(4));
    let (d, _) = dst.as_chunks_mut::<4>();
    let (s, _) = src.as_chunks::<4>();
    for (d, s) in d.iter_mut().zip(s) {
        for (d, &s) in d.iter_mut().zip(s) {
            *d = (*d).max(s);
        }
    }
}

/// Clock `i` of a list of clocks of 4 entries (the stride when at most 4 lanes are in use:
/// the explore bench's window, a fuzz campaign's), as one block: where a slice of a
/// length known only at run time computed and checked its bounds, then looped over its
/// chunks (a join or a copy was about 50 instructions, a sixth of a detector's access).
#[inline(always)]
fn four(v: &[u32], i: usize) -> &[u32; 4] {
    v[i * 4..].first_chunk::<4>().expect("a clock of 4 entries")
}

/// [`four`], mutable.
#[inline(always)]
fn four_mut(v: &mut [u32], i: usize) -> &mut [u32; 4] {
    v[i * 4..]
        .first_chunk_mut::<4>()
        .expect("a clock of 4 entries")
}

/// Joins block `src` into `dst` (entrywise maximum).
#[inline(always)]
fn join4(dst: &mut [u32; 4], src: &[u32; 4]) {
    for (d, &s) in dst.iter_mut().zip(src) {
        *d = (*d).max(s);
    }
}

/// The vector clocks of one pass (see the module's documentation).
pub(super) struct Clocks {
    /// Entries per clock: a power of two, at least 4 and at least the lanes in use (at
    /// most [`MAX_CLOCK_LANES`]).
    stride: usize,
    /// Lane `l`'s clock at `lane[l * stride ..][.. stride]`.
    lane: Vec<u32>,
    /// Per lane: the epoch the next invocation started in it begins at.
    next: Vec<u32>,
    /// The join of the clocks of every invocation finished so far in the pass.
    done: Vec<u32>,
    /// Release clocks of atomic words, `used` of them in this pass (a word's index into
    /// them is in its state).
    words: Vec<u32>,
    used: u32,
}

impl Clocks {
    pub fn new() -> Clocks {
        Clocks {
            stride: 0,
            lane: Vec::new(),
            next: Vec::new(),
            done: Vec::new(),
            words: Vec::new(),
            used: 0,
        }
    }

    /// Forgets the pass, keeping allocations (lane clocks are written when a lane starts).
    pub fn reset(&mut self) {
        self.next.fill(1);
        self.done.fill(0);
        self.used = 0;
    }

    /// The lane as a clock index, if its invocations get clocks.
    #[inline]
    pub fn tracked(&self, lane: Option<u32>) -> Option<usize> {
        lane.map(|l| l as usize).filter(|&l| l < self.stride)
    }

    /// Makes room for lanes `0..=lane` (up to [`MAX_CLOCK_LANES`]), keeping every clock.
    #[inline]
    pub fn ensure(&mut self, lane: usize) {
        if lane < self.stride || self.stride >= MAX_CLOCK_LANES {
            return;
        }
        self.widen(lane);
    }

    /// [`Clocks::ensure`] past the current stride.
    #[cold]
    fn widen(&mut self, lane: usize) {
        let stride = (lane + 1).next_power_of_two().clamp(4, MAX_CLOCK_LANES);
        let widen = |v: &[u32], old: usize, n: usize| -> Vec<u32> {
            let mut w = vec![0; n * stride];
            for i in 0..n {
                w[i * stride..i * stride + old].copy_from_slice(&v[i * old..(i + 1) * old]);
            }
            w
        };
        let old = self.stride;
        let lanes = self.lane.len().checked_div(old).unwrap_or(0);
        self.lane = widen(&self.lane, old, lanes);
        self.lane.resize(stride * stride, 0);
        self.words = widen(&self.words, old, self.used as usize);
        self.done.resize(stride, 0);
        self.next.resize(stride, 1);
        self.stride = stride;
    }

    /// An invocation starts in lane `l`: it knows what every finished one knew.
    #[inline]
    pub fn start(&mut self, l: usize) {
        let s = self.stride;
        if s == 4 {
            *four_mut(&mut self.lane, l) = *four(&self.done, 0);
            self.lane[l * 4 + l] = self.next[l];
            return;
        }
        copy(&mut self.lane[l * s..(l + 1) * s], &self.done);
        self.lane[l * s + l] = self.next[l];
    }

    /// The invocation in lane `l` finished: its successors in the lane start past its
    /// epochs, and every invocation started from now on knows what it knew.
    #[inline]
    pub fn finish(&mut self, l: usize) {
        let s = self.stride;
        self.next[l] = self.lane[l * s + l] + 1;
        if s == 4 {
            join4(four_mut(&mut self.done, 0), four(&self.lane, l));
            return;
        }
        join(&mut self.done, &self.lane[l * s..(l + 1) * s]);
    }

    /// The current epoch of the invocation in lane `l` (that of its next access).
    #[inline]
    pub fn epoch(&self, l: usize) -> u32 {
        self.lane[l * self.stride + l]
    }

    /// Whether the invocation in lane `me` knows (has synchronised with) an access made in
    /// lane `lane` at `epoch`: the access happens before whatever `me` does next.
    #[inline]
    pub fn knows(&self, me: Option<usize>, lane: u16, epoch: u32) -> bool {
        match me {
            Some(m) => {
                let l = lane as usize;
                l < self.stride && self.lane[m * self.stride + l] >= epoch
            }
            None => false,
        }
    }

    /// Lane `l` acquires the release clock `word` (an atomic read of a released value).
    #[inline]
    pub fn acquire(&mut self, l: usize, word: u32) {
        let s = self.stride;
        let w = (word - 1) as usize;
        if s == 4 {
            join4(four_mut(&mut self.lane, l), four(&self.words, w));
            return;
        }
        let w = &self.words[w * s..(w + 1) * s];
        join(&mut self.lane[l * s..(l + 1) * s], w);
    }

    /// Lane `l` releases into `word` (allocated here on a word's first release): the
    /// word's clock becomes the lane's (after an acquire of the same read-modify-write the
    /// lane's clock already holds what the word's did, so the release sequence goes on),
    /// and the lane moves to its next epoch.
    #[inline]
    pub fn release(&mut self, l: usize, word: &mut u32) {
        let s = self.stride;
        if *word == NO_CLOCK {
            self.used += 1;
            *word = self.used;
            let need = self.used as usize * s;
            if self.words.len() < need {
                self.words.resize(need, 0);
            }
        }
        let w = (*word - 1) as usize;
        if s == 4 {
            *four_mut(&mut self.words, w) = *four(&self.lane, l);
            self.lane[l * 4 + l] += 1;
            return;
        }
        let (words, lane) = (&mut self.words, &self.lane);
        copy(&mut words[w * s..(w + 1) * s], &lane[l * s..(l + 1) * s]);
        self.lane[l * s + l] += 1;
    }
}
