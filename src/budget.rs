//! Peak memory of a run, estimated before anything large is allocated, and the budget it
//! must fit in (`--memory-limit`, by default half of the machine's physical memory).
//!
//! The estimate is a model measured on this implementation, not a sum of buffer sizes: a
//! run's peak holds far more than its declared storage (the scheduled executor's hazard
//! detector keeps about 300 bytes per word of shared memory touched; results are copied
//! into host-side captures and images; the truth of `check` holds every fragment). For
//! each algorithm and each kind of executor (direct: ordered and parallel; scheduled) the
//! peak resident set was measured (VmHWM) on scenes of low and high depth complexity at
//! two values of k, and fitted as
//!
//! ```text
//! base + triangles x T + pixels x (a + b k) + fragments x c + executor slots
//! ```
//!
//! with the fitted coefficients rounded up by a tenth. `bash ci/memory.sh VERB SCENE SIZE
//! EXEC` prints peak, estimate and their ratio for every algorithm (on this machine, over
//! 140 runs of 5 scenes, sizes 96 to 640 and the three executors: 0.44 to 1.06; at
//! 1024x1024 and 2048x2048: 0.63 to 0.88). `fragments` is estimated from the
//! projected area of every triangle ([`estimate_fragments`]); executor slots are the
//! scheduled window, or the lanes of every thread's warp. `tests/memory.rs` checks that
//! the measured peak stays within 1.5x of the estimate for several algorithms and
//! executors.

use fragrace_emu::ExecMode;

use crate::run::{Loaded, RunSpec};

/// The process before any run (binary, allocator, threads), in bytes.
const BASE: f64 = 8.0e6;
/// Per triangle of the mesh: the mesh itself, projected vertices, setup records and bins.
const PER_TRIANGLE: f64 = 200.0;
/// What the scheduled executor's hazard detector keeps per word of shared memory touched.
const PER_DETECTED_WORD: f64 = 300.0;
/// Per slot of the scheduled window (invocation, its future, the detector's lane).
const PER_WINDOW_SLOT: f64 = 1536.0;
/// Per lane of a warp of the parallel executor, per thread.
const PER_LANE: f64 = 1536.0;

/// Bytes per pixel, per pixel and unit of k, and per fragment: direct executors
/// (ordered, parallel), then the scheduled executor. Measured (see the module docs).
#[rustfmt::skip] // one algorithm per line
const MODELS: &[(&str, [f64; 3], [f64; 3])] = &[
    ("count", [14.1, 0.0, 1.8], [105.6, 0.0, 158.4]),
    ("count-plain", [14.1, 0.0, 1.8], [52.8, 0.0, 369.6]),
    ("opaque", [96.8, 0.0, 3.5], [158.4, 0.0, 3.5]),
    ("truth", [21.1, 0.0, 29.9], [35.2, 0.0, 29.9]),
    ("ll", [136.4, 0.0, 10.6], [756.8, 1.8, 1108.8]),
    ("fab", [1188.0, 0.0, 3.5], [1364.0, 0.0, 871.2]),
    ("sb", [149.6, 0.0, 3.5], [1170.4, 0.0, 915.2]),
    ("dfb", [114.4, 3.5, 3.5], [1170.4, 0.0, 888.8]),
    ("bun-ll", [268.4, 0.9, 18.5], [2103.2, 1.8, 1183.6]),
    ("kb-rmw", [79.2, 37.0, 3.5], [35.2, 721.6, 3097.6]),
    ("kb-multipass", [132.0, 35.2, 15.8], [35.2, 721.6, 3440.8]),
    ("srab", [453.2, 0.0, 6.2], [519.2, 0.0, 272.8]),
    ("kb-atomic32", [132.0, 42.2, 3.5], [220.0, 732.2, 127.6]),
    ("kb-atomic64", [154.0, 32.6, 3.5], [259.6, 369.6, 3.5]),
    ("kb-spinlock", [114.4, 37.0, 3.5], [35.2, 721.6, 1628.0]),
    ("kb-interlock", [140.8, 31.7, 26.4], [303.6, 721.6, 4.4]),
    ("kb-interlock-unordered", [57.2, 38.7, 29.0], [277.2, 721.6, 52.8]),
    ("kplus", [136.4, 15.8, 43.1], [1135.2, 8.8, 334.4]),
    ("kplus-heap", [96.8, 18.5, 44.9], [1144.0, 8.8, 316.8]),
    ("wboit", [162.8, 0.0, 5.3], [233.2, 0.0, 237.6]),
    ("f2b", [101.2, 14.1, 13.2], [92.4, 14.1, 308.0]),
    ("f2b-2p", [171.6, 14.1, 13.2], [176.0, 14.1, 360.8]),
    ("f2b-3p", [176.0, 14.1, 14.1], [180.4, 14.1, 378.4]),
    ("f2b-ll", [105.6, 14.1, 37.0], [286.0, 14.1, 294.8]),
    ("f2b-fab", [228.8, 14.1, 20.2], [352.0, 14.1, 290.4]),
    ("f2b-kb", [228.8, 14.1, 15.8], [255.2, 14.1, 321.2]),
    ("dual", [180.4, 0.0, 31.7], [96.8, 0.0, 453.2]),
    ("dual-ll", [88.0, 0.0, 54.6], [598.4, 0.0, 325.6]),
    // Fitted by `python3 ci/memory_fit.py f2b2` (2026-11-27).
    ("f2b2", [161.5, 2.9, 1.8], [103.7, 0.0, 330.2]),
];
/// An algorithm the table does not know (one added since it was measured: `python3
/// ci/memory_fit.py` prints the rows of those): the largest coefficients of the table, so
/// its estimate errs high (a run refused that would have fit, never one admitted that does
/// not).
const UNKNOWN: ([f64; 3], [f64; 3]) = ([1350.0, 48.0, 62.0], [2390.0, 832.0, 3910.0]);

/// The estimate of a run's peak memory, with its parts.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MemoryEstimate {
    /// Estimated peak resident memory, in bytes.
    pub bytes: u64,
    /// Fragments per geometry pass, estimated from the triangles' projected areas.
    pub fragments: u64,
    /// The process, the mesh, per-pixel storage, per-fragment storage, executor slots and
    /// (for checks) the truth, in bytes.
    pub parts: Vec<(String, u64)>,
}

/// A run that does not fit the budget, or a budget that does not parse.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum BudgetError {
    #[error("{subject} needs an estimated {} ({}), more than the memory limit of {} ({limit_source}); {advice}, or raise --memory-limit", human(*estimate), parts, human(*limit))]
    OverLimit {
        /// "this run", "this campaign".
        subject: &'static str,
        /// What would make it smaller.
        advice: &'static str,
        estimate: u64,
        limit: u64,
        /// Where the limit comes from.
        limit_source: String,
        /// The largest parts of the estimate, in words.
        parts: String,
    },
    #[error("--memory-limit `{0}`: expected a size such as 8G, 512M, 300k or a number of bytes, above 0")]
    BadSize(String),
}

/// A size in bytes for people (decimal units).
pub fn human(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else {
        format!("{:.1} kB", b / 1e3)
    }
}

/// Parses a memory size: bytes, or with a suffix k, M, G, T (powers of 1000; `KiB`-style
/// suffixes are powers of 1024).
pub fn parse_size(s: &str) -> Result<u64, BudgetError> {
    let bad = || BudgetError::BadSize(s.to_string());
    let t = s.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let v: f64 = num.parse().map_err(|_| bad())?;
    let mult = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" => 1e3,
        "m" | "mb" => 1e6,
        "g" | "gb" => 1e9,
        "t" | "tb" => 1e12,
        "kib" => 1024.0,
        "mib" => 1024.0 * 1024.0,
        "gib" => 1024.0 * 1024.0 * 1024.0,
        "tib" => 1024.0 * 1024.0 * 1024.0 * 1024.0,
        _ => return Err(bad()),
    };
    let bytes = v * mult;
    if !(1.0..1.8e19).contains(&bytes) {
        return Err(bad());
    }
    Ok(bytes as u64)
}

/// The machine's physical memory (`MemTotal` of `/proc/meminfo`), if it can be read.
pub fn physical_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The default budget and where it comes from: half of the physical memory, or 4 GB when
/// that cannot be read.
pub fn default_limit() -> (u64, String) {
    match physical_memory() {
        Some(m) => (
            m / 2,
            format!("the default, half of this machine's {}", human(m)),
        ),
        None => (
            4_000_000_000,
            "the default when the physical memory cannot be read".into(),
        ),
    }
}

/// The budget: `--memory-limit` if given, else [`default_limit`].
pub fn limit(given: Option<&str>) -> Result<(u64, String), BudgetError> {
    match given {
        Some(s) => Ok((parse_size(s)?, format!("--memory-limit {s}"))),
        None => Ok(default_limit()),
    }
}

/// Fragments of one geometry pass over the whole mesh, estimated from each triangle's
/// projected area (clipped to the viewport by its bounding box; a triangle reaching
/// behind the eye counts as the whole viewport). Both facings count.
pub fn estimate_fragments(spec: &RunSpec, loaded: &Loaded) -> u64 {
    let (w, h) = (f64::from(spec.width), f64::from(spec.height));
    let m = loaded.view_proj.as_dmat4();
    let mesh = &loaded.scene.mesh;
    let mut total = 0.0f64;
    for tri in &mesh.indices {
        let mut pts = [(0.0f64, 0.0f64); 3];
        let mut behind = false;
        for (p, &i) in pts.iter_mut().zip(tri) {
            let Some(v) = mesh.positions.get(i as usize) else {
                continue;
            };
            let c = m * v.as_dvec3().extend(1.0);
            if c.w <= 1e-9 {
                behind = true;
                break;
            }
            *p = ((c.x / c.w * 0.5 + 0.5) * w, (c.y / c.w * 0.5 + 0.5) * h);
        }
        if behind {
            total += w * h;
            continue;
        }
        let (x0, x1) = (
            pts.iter()
                .map(|p| p.0)
                .fold(f64::INFINITY, f64::min)
                .max(0.0),
            pts.iter()
                .map(|p| p.0)
                .fold(f64::NEG_INFINITY, f64::max)
                .min(w),
        );
        let (y0, y1) = (
            pts.iter()
                .map(|p| p.1)
                .fold(f64::INFINITY, f64::min)
                .max(0.0),
            pts.iter()
                .map(|p| p.1)
                .fold(f64::NEG_INFINITY, f64::max)
                .min(h),
        );
        if x1 <= x0 || y1 <= y0 {
            continue;
        }
        let area = 0.5
            * ((pts[1].0 - pts[0].0) * (pts[2].1 - pts[0].1)
                - (pts[2].0 - pts[0].0) * (pts[1].1 - pts[0].1))
                .abs();
        total += area.min((x1 - x0) * (y1 - y0));
    }
    total.ceil() as u64
}

fn model(algo: &str, scheduled: bool) -> [f64; 3] {
    let (direct, sched) = MODELS
        .iter()
        .find(|m| m.0 == algo)
        .map_or(UNKNOWN, |m| (m.1, m.2));
    if scheduled {
        sched
    } else {
        direct
    }
}

/// The estimated peak memory of running `spec` on `loaded` (and, with `with_truth`, of
/// computing the truth and comparing with it first, as `check` and `replay` do).
pub fn estimate(spec: &RunSpec, loaded: &Loaded, with_truth: bool) -> MemoryEstimate {
    estimate_for(
        spec,
        estimate_fragments(spec, loaded),
        loaded.scene.mesh.indices.len(),
        with_truth,
    )
}

/// [`estimate`] for a scene of `triangles` that makes `fragments` per geometry pass.
pub fn estimate_for(
    spec: &RunSpec,
    fragments: u64,
    triangles: usize,
    with_truth: bool,
) -> MemoryEstimate {
    let pixels = f64::from(spec.width) * f64::from(spec.height);
    let frags = fragments as f64;
    let k = f64::from(spec.params.k);
    let scheduled = matches!(spec.exec.mode, ExecMode::Scheduled(_));
    let [a, b, c] = model(&spec.algo, scheduled);
    let slots = match &spec.exec.mode {
        ExecMode::Scheduled(s) => (
            format!("executor slots (window {})", s.window),
            s.window as f64 * PER_WINDOW_SLOT,
        ),
        ExecMode::Parallel => (
            format!(
                "executor slots (--lanes {} x {} threads)",
                spec.exec.batch, spec.exec.threads
            ),
            spec.exec.batch as f64 * spec.exec.threads as f64 * PER_LANE,
        ),
        ExecMode::Ordered => ("executor slots".to_string(), PER_LANE),
    };
    let mut parts = vec![
        ("process".to_string(), BASE),
        (
            format!("mesh ({triangles} triangles)"),
            triangles as f64 * PER_TRIANGLE,
        ),
        (
            format!(
                "per-pixel storage ({}x{} pixels, k {})",
                spec.width, spec.height, spec.params.k
            ),
            pixels * (a + b * k),
        ),
        (
            format!("per-fragment storage (about {fragments} fragments)"),
            frags * c,
        ),
        slots,
    ];
    if let Some(o) = spec.params.occupancy {
        // The stage's map, range and depth buffer, plus what the scheduled detector keeps
        // per map word touched (at most one a fragment); and the same run without culling,
        // which `render` and `check` run after it for what culling saved.
        let touched = if scheduled {
            frags * PER_DETECTED_WORD
        } else {
            0.0
        };
        parts.push((
            format!("occupancy map (d {})", o.d),
            pixels * 4.0 * (f64::from(o.d) + 3.0) + touched,
        ));
        parts.push((
            "the run without culling (for what culling saved)".to_string(),
            pixels * (a + b * k) + frags * c,
        ));
    }
    if with_truth {
        let [ta, _, tc] = model("truth", false);
        parts.push(("the truth".to_string(), pixels * ta + frags * tc));
    }
    let parts: Vec<(String, u64)> = parts
        .into_iter()
        .map(|(n, v)| (n, v.min(u64::MAX as f64 / 8.0) as u64))
        .collect();
    MemoryEstimate {
        bytes: parts.iter().map(|p| p.1).fold(0u64, u64::saturating_add),
        fragments,
        parts,
    }
}

/// Refuses a run whose estimate is above `limit` (from `source`), naming its largest parts.
pub fn check(est: &MemoryEstimate, limit: u64, source: &str) -> Result<(), BudgetError> {
    check_subject(
        est,
        limit,
        source,
        "this run",
        "use fewer pixels, a smaller k, window or --lanes",
    )
}

/// [`check`] of a fuzz campaign's runs in flight.
pub fn check_campaign(est: &MemoryEstimate, limit: u64, source: &str) -> Result<(), BudgetError> {
    check_subject(
        est,
        limit,
        source,
        "this campaign",
        "use fewer --jobs or a smaller --max-size",
    )
}

fn check_subject(
    est: &MemoryEstimate,
    limit: u64,
    source: &str,
    subject: &'static str,
    advice: &'static str,
) -> Result<(), BudgetError> {
    if est.bytes <= limit {
        return Ok(());
    }
    let mut parts = est.parts.clone();
    parts.sort_by_key(|p| std::cmp::Reverse(p.1));
    let parts = parts
        .iter()
        .take(2)
        .map(|(n, v)| match est.parts.len() {
            1 => n.clone(),
            _ => format!("{} {n}", human(*v)),
        })
        .collect::<Vec<_>>()
        .join(", ");
    Err(BudgetError::OverLimit {
        subject,
        advice,
        estimate: est.bytes,
        limit,
        limit_source: source.to_string(),
        parts,
    })
}

/// The peak resident memory of this process so far (`VmHWM` of `/proc/self/status`), where
/// the system reports it.
pub fn peak_rss() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = text.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
