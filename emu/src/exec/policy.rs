//! Scheduling policies of the `scheduled` executor.

use std::fmt;
use std::str::FromStr;

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use crate::kernel::FragInput;

/// How the `scheduled` executor picks the next invocation to step.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Policy {
    /// Uniformly random among the runnable invocations.
    Random,
    /// Probabilistic concurrency testing (Burckhardt et al. 2010) with bug depth `depth`:
    /// random priorities, `depth - 1` priority change points; the highest-priority
    /// runnable invocation always runs.
    Pct { depth: u32 },
    /// Lockstep warps of `lanes` invocations (consecutive in API order): lanes take one step
    /// each in turn, warps round robin.
    Warp { lanes: u32 },
    /// Round robin, latest primitive first in each round.
    Reverse,
    /// Round robin, earliest first in each round (API order).
    Fifo,
    /// Round robin, farthest fragment first in each round: fragments make progress in
    /// descending depth, the worst case for k-buffer culling.
    FarFirst,
    /// An explicit schedule: at step k, run the `bytes[k] % n`-th runnable invocation (in
    /// API order); earliest first once the bytes run out. Any byte string is valid, which
    /// makes schedules fuzzable and shrinkable; a recorded schedule replays exactly.
    Bytes(Vec<u8>),
}

impl fmt::Display for Policy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Policy::Random => write!(f, "random"),
            Policy::Pct { depth } => write!(f, "pct:{depth}"),
            Policy::Warp { lanes } => write!(f, "warp:{lanes}"),
            Policy::Reverse => write!(f, "reverse"),
            Policy::Fifo => write!(f, "fifo"),
            Policy::FarFirst => write!(f, "far-first"),
            Policy::Bytes(b) => {
                write!(f, "bytes:")?;
                for x in b {
                    write!(f, "{x:02x}")?;
                }
                Ok(())
            }
        }
    }
}

/// A policy string that does not parse.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum PolicyParseError {
    /// No policy has this name.
    #[error(
        "unknown policy `{0}`: expected random, pct:D, warp:N, reverse, fifo, far-first or bytes:HEX"
    )]
    Unknown(String),
    /// A known policy with a value out of its range (`pct:0`, `warp:x`).
    #[error("policy `{policy}`: {name} `{value}` must be an integer from {min} to {max}")]
    BadValue {
        policy: String,
        name: &'static str,
        value: String,
        min: u32,
        max: u32,
    },
    /// `bytes:` with something other than pairs of hexadecimal digits.
    #[error(
        "policy `{0}`: bytes:HEX takes an even number of hexadecimal digits (00 to ff per step)"
    )]
    BadHex(String),
}

impl FromStr for Policy {
    type Err = PolicyParseError;
    fn from_str(s: &str) -> Result<Policy, PolicyParseError> {
        let (name, arg) = match s.split_once(':') {
            Some((n, a)) => (n, Some(a)),
            None => (s, None),
        };
        let num = |d: u32, what: &'static str| -> Result<u32, PolicyParseError> {
            match arg {
                None => Ok(d),
                Some(a) => a.parse::<u32>().ok().filter(|&v| v >= 1).ok_or_else(|| {
                    PolicyParseError::BadValue {
                        policy: s.to_string(),
                        name: what,
                        value: a.to_string(),
                        min: 1,
                        max: u32::MAX,
                    }
                }),
            }
        };
        Ok(match name {
            "random" => Policy::Random,
            "pct" => Policy::Pct {
                depth: num(3, "depth")?,
            },
            "warp" => Policy::Warp {
                lanes: num(32, "lanes")?,
            },
            "reverse" => Policy::Reverse,
            "fifo" => Policy::Fifo,
            "far-first" => Policy::FarFirst,
            "bytes" => {
                let bad = || PolicyParseError::BadHex(s.to_string());
                let a = arg.unwrap_or("");
                if a.len() % 2 != 0 || !a.is_ascii() {
                    return Err(bad());
                }
                let bytes = (0..a.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(&a[i..i + 2], 16))
                    .collect::<Result<Vec<u8>, _>>()
                    .map_err(|_| bad())?;
                Policy::Bytes(bytes)
            }
            _ => return Err(PolicyParseError::Unknown(s.to_string())),
        })
    }
}

impl Policy {
    /// The named policies (for sweeps over every policy).
    pub fn all() -> Vec<Policy> {
        vec![
            Policy::Random,
            Policy::Pct { depth: 3 },
            Policy::Warp { lanes: 32 },
            Policy::Reverse,
            Policy::Fifo,
            Policy::FarFirst,
        ]
    }
}

/// A candidate for the next step.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Candidate {
    pub seq: u64,
    /// The invocation's place in the round-robin order of an ordering policy (see
    /// [`Chooser::rank_inputs`]; 0 under the other policies).
    pub rank: u64,
    /// The executor's slot of the invocation (unique among those in flight): per-invocation
    /// policy state is indexed by it, not hashed by `seq`.
    pub slot: u32,
}

/// Which policy a [`Chooser`] runs, as the choice at every step dispatches on it: a plain
/// tag, where matching the [`Policy`] itself first decoded its discriminant from the
/// capacity of `Bytes`'s vector (a dozen instructions a step).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Random,
    Pct,
    Other,
}

impl Kind {
    fn of(policy: &Policy) -> Kind {
        match policy {
            Policy::Random => Kind::Random,
            Policy::Pct { .. } => Kind::Pct,
            _ => Kind::Other,
        }
    }
}

/// The running state of a policy during one scheduled pass.
pub(crate) struct Chooser {
    policy: Policy,
    kind: Kind,
    rng: SmallRng,
    /// PCT: priority per in-flight slot (higher runs first), and the change points still
    /// ahead, latest first (the next is the last: taking it is a `pop`, where the earliest
    /// first made it a `remove(0)`, a call to `memmove`).
    priorities: Vec<u64>,
    change_points: Vec<u64>,
    next_low: u64,
    /// Warp: last chosen seq.
    cursor: Option<u64>,
    /// Ordering policies: rank of the last chosen (round robin).
    round_cursor: Option<u64>,
    /// Ordering policies: per input of the pass (by index), its rank in the policy's order
    /// ([`Chooser::rank_inputs`]), and the sort's scratch.
    ranks: Vec<u64>,
    order: Vec<(u128, usize)>,
    /// Bytes: position.
    pos: usize,
    /// PCT: the last choice, and the version of the candidates it was made among (see
    /// [`Chooser::choose`]): while the candidates and the priorities stay as they were,
    /// the highest priority is where it was, and the scan over the candidates is skipped
    /// (it was 7 % of the explore bench's instructions).
    pct_best: usize,
    pct_version: Option<u64>,
}

impl Chooser {
    /// `steps_estimate` spreads PCT's change points over the expected run length.
    pub fn new(policy: &Policy, seed: u64, steps_estimate: u64) -> Chooser {
        let mut rng = SmallRng::seed_from_u64(seed ^ 0x6672_6167_7261_6365);
        let mut change_points = Vec::new();
        if let Policy::Pct { depth } = policy {
            for _ in 1..*depth {
                change_points.push(rng.gen_range(0..steps_estimate.max(1)));
            }
            change_points.sort_unstable_by(|a, b| b.cmp(a));
        }
        Chooser {
            policy: policy.clone(),
            kind: Kind::of(policy),
            rng,
            priorities: Vec::new(),
            change_points,
            next_low: 0,
            cursor: None,
            round_cursor: None,
            ranks: Vec::new(),
            order: Vec::new(),
            pos: 0,
            pct_best: 0,
            pct_version: None,
        }
    }

    /// Starts over for another run (keeps allocations).
    pub fn reset(&mut self, policy: &Policy, seed: u64, steps_estimate: u64) {
        if &self.policy != policy {
            self.policy = policy.clone();
            self.kind = Kind::of(policy);
        }
        self.rng = SmallRng::seed_from_u64(seed ^ 0x6672_6167_7261_6365);
        self.change_points.clear();
        if let Policy::Pct { depth } = &self.policy {
            for _ in 1..*depth {
                self.change_points
                    .push(self.rng.gen_range(0..steps_estimate.max(1)));
            }
            // (One change point under `pct:2`, and nothing to sort.)
            if self.change_points.len() > 1 {
                self.change_points.sort_unstable_by(|a, b| b.cmp(a));
            }
        }
        // (Priorities are written at admission: no need to clear them.)
        self.next_low = 0;
        self.cursor = None;
        self.round_cursor = None;
        self.pos = 0;
        self.pct_version = None;
    }

    /// The key of an input in an ordering policy's round-robin order (smallest first),
    /// packed into one integer that orders as the tuple it packs: ascending sequence
    /// numbers (`Fifo`), descending ones (`Reverse`: `u64::MAX - seq` orders as `-seq`), the
    /// farthest depth first, then ascending sequence numbers (`FarFirst`). `None` for the
    /// policies that take no turns.
    fn round_key(&self) -> Option<fn(&FragInput) -> u128> {
        match self.policy {
            Policy::Fifo => Some(|f| u128::from(f.seq)),
            Policy::Reverse => Some(|f| u128::from(u64::MAX - f.seq)),
            Policy::FarFirst => Some(|f| {
                (u128::from(crate::memory::f32_order_key(-f.depth)) << 64) | u128::from(f.seq)
            }),
            _ => None,
        }
    }

    /// Ranks the pass's `inputs` in the ordering policy's order, once per pass: a candidate
    /// then carries its rank, and the round robin compares one integer per candidate instead
    /// of computing and comparing its key at every step (the scan over the candidates with
    /// their keys was a fifth of a `kb-interlock` campaign's instructions,
    /// docs/performance.md). A rank is any `u64` that orders as the key does (equal keys,
    /// equal ranks): the sequence number itself (`Fifo`), its complement (`Reverse`), and
    /// for `FarFirst` the depth's order key above the sequence number's offset from the
    /// pass's first when those offsets fit in 32 bits (always, but for passes of more than
    /// 2^32 fragments), else the key's place among the pass's sorted keys. Nothing for the
    /// other policies.
    pub fn rank_inputs(&mut self, inputs: &[FragInput]) {
        self.ranks.clear();
        match self.policy {
            Policy::Fifo => self.ranks.extend(inputs.iter().map(|f| f.seq)),
            Policy::Reverse => self.ranks.extend(inputs.iter().map(|f| u64::MAX - f.seq)),
            Policy::FarFirst => {
                let lo = inputs.iter().map(|f| f.seq).min().unwrap_or(0);
                let hi = inputs.iter().map(|f| f.seq).max().unwrap_or(0);
                if hi - lo <= u64::from(u32::MAX) {
                    self.ranks.extend(inputs.iter().map(|f| {
                        u64::from(crate::memory::f32_order_key(-f.depth)) << 32 | (f.seq - lo)
                    }));
                } else {
                    self.rank_by_sorting(inputs);
                }
            }
            _ => {}
        }
    }

    /// [`Chooser::rank_inputs`] by sorting the keys ([`Chooser::round_key`]): dense ranks.
    fn rank_by_sorting(&mut self, inputs: &[FragInput]) {
        let Some(key) = self.round_key() else { return };
        self.order.clear();
        self.order
            .extend(inputs.iter().enumerate().map(|(i, f)| (key(f), i)));
        // (The index makes the pairs distinct: an unstable sort gives one order.)
        self.order.sort_unstable();
        self.ranks.resize(inputs.len(), 0);
        let mut rank = 0u64;
        for (r, &(k, i)) in self.order.iter().enumerate() {
            if r > 0 && k != self.order[r - 1].0 {
                rank += 1;
            }
            self.ranks[i] = rank;
        }
    }

    /// The rank of input `i` of the pass (see [`Chooser::rank_inputs`]; 0 under the policies
    /// that take no turns).
    #[inline]
    pub fn rank(&self, i: usize) -> u64 {
        self.ranks.get(i).copied().unwrap_or(0)
    }

    /// Round robin in rank order: the first candidate after the last one chosen, wrapping
    /// around. One pass, one integer per candidate: with `lo` one above the last chosen
    /// rank, `rank - lo` (wrapping) is at most `u64::MAX - lo` for the ranks from `lo` up
    /// and more for the others, in rank order within each group: its smallest is the
    /// smallest rank from `lo` up when there is one, and otherwise the smallest rank of all.
    /// (After the rank `u64::MAX`, `lo` wraps to 0: the smallest of all, as nothing is above.)
    #[inline]
    fn round(&mut self, cands: &[Candidate]) -> usize {
        let lo = self.round_cursor.map_or(0, |r| r.wrapping_add(1));
        let mut best = 0;
        let mut best_d = cands[0].rank.wrapping_sub(lo);
        for (i, c) in cands.iter().enumerate().skip(1) {
            let d = c.rank.wrapping_sub(lo);
            if d < best_d {
                (best, best_d) = (i, d);
            }
        }
        self.round_cursor = Some(cands[best].rank);
        best
    }

    /// Bytes of a [`Policy::Bytes`] schedule consumed so far.
    pub fn bytes_used(&self) -> usize {
        self.pos
    }

    /// A new invocation entered the window in slot `slot`.
    #[inline]
    pub fn admit(&mut self, slot: u32) {
        if let Policy::Pct { depth } = self.policy {
            // Initial priorities sit above the `depth` low values used at change points.
            let p = depth as u64 + 1 + self.rng.gen_range(0..1u64 << 40);
            let slot = slot as usize;
            if self.priorities.len() <= slot {
                self.priorities.resize(slot + 1, 0);
            }
            self.priorities[slot] = p;
            // (Priorities changed: the last choice no longer stands.)
            self.pct_version = None;
        }
    }

    /// Picks one of `cands` (sorted by seq, non-empty) at global step `step`; returns its
    /// position in `cands`. `version` names the list of candidates: the caller gives the
    /// same version only for the same candidates in the same order as at an earlier call
    /// (and changes it whenever it adds, removes or reorders one), or `None` for a list it
    /// does not track. A policy may then reuse what it computed for that list.
    #[inline]
    pub fn choose(&mut self, cands: &[Candidate], version: Option<u64>, step: u64) -> usize {
        debug_assert!(!cands.is_empty());
        // The cheapest and commonest policy inline, the others out of line: a call to the
        // whole match cost a few dozen instructions per step in saved registers alone.
        // PCT inline too when nothing changed since its last choice: the same candidates,
        // no admission since (priorities), and no change point due.
        match self.kind {
            Kind::Random => self.rng.gen_range(0..cands.len()),
            Kind::Pct
                if version.is_some()
                    && self.pct_version == version
                    && self.change_points.last().is_none_or(|&c| c > step) =>
            {
                self.pct_best
            }
            _ => self.choose_other(cands, version, step),
        }
    }

    #[inline(never)]
    fn choose_other(&mut self, cands: &[Candidate], version: Option<u64>, step: u64) -> usize {
        match &self.policy {
            Policy::Random => self.rng.gen_range(0..cands.len()),
            // The ordering policies take turns like a GPU's resident warps do: every
            // runnable invocation takes one step per round, the round in the policy's order.
            // (Run-to-completion in that order is the same policy with a window of 1.)
            // (In the order of `round_key`, by the candidates' ranks.)
            Policy::Fifo | Policy::Reverse | Policy::FarFirst => self.round(cands),
            Policy::Pct { .. } => {
                // The first of the highest priority (every candidate was admitted).
                let pick = |prio: &[u64]| {
                    let mut best = 0;
                    let mut top = prio[cands[0].slot as usize];
                    for (i, c) in cands.iter().enumerate().skip(1) {
                        let p = prio[c.slot as usize];
                        if p > top {
                            (best, top) = (i, p);
                        }
                    }
                    best
                };
                let mut best = pick(&self.priorities);
                while self.change_points.last().is_some_and(|&c| c <= step) {
                    self.change_points.pop();
                    // The running invocation drops below everyone admitted so far.
                    self.next_low += 1;
                    let low = (self.change_points.len() as u64 + 1).saturating_sub(self.next_low);
                    self.priorities[cands[best].slot as usize] = low;
                    best = pick(&self.priorities);
                }
                (self.pct_best, self.pct_version) = (best, version);
                best
            }
            Policy::Warp { lanes } => {
                let lanes = *lanes as u64;
                let i = match self.cursor {
                    None => 0,
                    Some(cur) => {
                        let warp = cur / lanes;
                        cands
                            .iter()
                            .position(|c| c.seq > cur && c.seq / lanes == warp)
                            .or_else(|| cands.iter().position(|c| c.seq / lanes > warp))
                            .unwrap_or(0)
                    }
                };
                self.cursor = Some(cands[i].seq);
                i
            }
            Policy::Bytes(bytes) => {
                let i = match bytes.get(self.pos) {
                    Some(&b) => b as usize % cands.len(),
                    None => 0,
                };
                self.pos += 1;
                i
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The round robin as it was before its keys were packed and ranked: tuples of an
    /// order key and an `i128`, compared as `Option`s at every step.
    fn round_tuples(
        cursor: &mut Option<(u32, i128)>,
        cands: &[Candidate],
        key: impl Fn(&Candidate) -> (f32, i128),
    ) -> usize {
        let k = |c: &Candidate| {
            let (a, b) = key(c);
            (crate::memory::f32_order_key(a), b)
        };
        let mut best: Option<(usize, (u32, i128))> = None;
        let mut first: Option<(usize, (u32, i128))> = None;
        for (i, c) in cands.iter().enumerate() {
            let kc = k(c);
            if first.is_none_or(|(_, f)| kc < f) {
                first = Some((i, kc));
            }
            if cursor.is_none_or(|a| kc > a) && best.is_none_or(|(_, b)| kc < b) {
                best = Some((i, kc));
            }
        }
        let (i, kc) = best.or(first).expect("not empty");
        *cursor = Some(kc);
        i
    }

    #[test]
    fn ordering_policies_choose_as_the_tuple_keys_did() {
        let mut rng = SmallRng::seed_from_u64(5);
        // A pass's inputs: sequence numbers of every magnitude (FarFirst ranks them by
        // sorting), or a pass's own (their offsets fit in 32 bits), both ends of the range
        // included; a few repeated (equal keys, equal ranks); depths colliding often
        // (FarFirst's ties).
        let mut universes = Vec::new();
        for wide in [true, false] {
            let mut inputs: Vec<FragInput> = (0..400)
                .map(|_| {
                    let seq = if wide {
                        rng.gen::<u64>() >> rng.gen_range(0..64)
                    } else {
                        (1 << 40) + rng.gen_range(0..1000)
                    };
                    FragInput {
                        seq,
                        depth: [0.25f32, 0.5, -0.0, 0.0, 1.0, f32::NAN][(seq % 6) as usize],
                        ..FragInput::default()
                    }
                })
                .collect();
            if wide {
                inputs[0].seq = 0;
                inputs[1].seq = u64::MAX;
            }
            for i in 0..20 {
                inputs[i * 7] = inputs[i * 11];
            }
            universes.push(inputs);
        }
        for (policy, inputs) in [Policy::Fifo, Policy::Reverse, Policy::FarFirst]
            .into_iter()
            .flat_map(|p| universes.iter().map(move |u| (p.clone(), u)))
        {
            let mut chooser = Chooser::new(&policy, 1, 100);
            chooser.rank_inputs(inputs);
            let mut cursor = None;
            let mut live: Vec<usize> = Vec::new();
            for step in 0..4000 {
                // Candidates come and go, in any order.
                if live.is_empty() || rng.gen_bool(0.3) {
                    let i = rng.gen_range(0..inputs.len());
                    if !live.contains(&i) {
                        live.push(i);
                    }
                }
                if live.len() > 1 && rng.gen_bool(0.2) {
                    live.swap_remove(rng.gen_range(0..live.len()));
                }
                let cands: Vec<Candidate> = live
                    .iter()
                    .map(|&i| Candidate {
                        seq: inputs[i].seq,
                        rank: chooser.rank(i),
                        slot: 0,
                    })
                    .collect();
                let depth = |c: &Candidate| {
                    let i = live[cands.iter().position(|x| std::ptr::eq(x, c)).expect("in")];
                    inputs[i].depth
                };
                let want = match policy {
                    Policy::Fifo => round_tuples(&mut cursor, &cands, |c| (0.0, c.seq as i128)),
                    Policy::Reverse => {
                        round_tuples(&mut cursor, &cands, |c| (0.0, -(c.seq as i128)))
                    }
                    _ => round_tuples(&mut cursor, &cands, |c| (-depth(c), c.seq as i128)),
                };
                assert_eq!(
                    chooser.choose(&cands, None, step),
                    want,
                    "{policy} at step {step}"
                );
            }
        }
    }
}
