//! Table 1 of "Depth-Fighting Aware Methods for Multifragment Rendering" (section 4), measured
//! against its formulas for every algorithm fragrace has, on a stack of coplanar quads (every
//! covered pixel has C fragments at one depth):
//!
//! - memory per pixel: the formula each algorithm declares (`fragrace list`), evaluated with
//!   this run's k, K, D, B and n (fragments per pixel), against the bytes it allocated per
//!   pixel;
//! - passes: the declared geometry passes, where they do not depend on the scene, against
//!   the passes run;
//! - R_h, the robustness ratio (section 3), against Table 1's robustness column written for
//!   this scene.

use fragrace_kernels::{AlgoInfo, Capacity, Params};
use serde_json::{json, Value};

use super::{ctx, Paper, PaperConfig, Progress, ReportError, Section, Table};
use crate::run::{self, RunSpec, SceneSpec};

/// Coplanar quads per pixel of the scene.
pub const COPLANAR: u32 = 16;
/// Slots of the fixed-size buffers of the z-fighting free peelers and SRAB's samples (the
/// paper's K = 8; `K = 8` in their declared memory).
pub const FIXED_K: u32 = 8;

/// The variables of a memory formula.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vars {
    /// k of the k-buffers (`k`).
    pub k: f64,
    /// Fixed slots (`K`).
    pub fixed_k: f64,
    /// FAB's slots per pixel (`D`).
    pub d: f64,
    /// Buckets (`B`).
    pub b: f64,
    /// Fragments per pixel, over every pixel of the image (`n`).
    pub n: f64,
}

/// The leading formula of a declared memory (`"4 + 12 n bytes (head; ...)"` gives
/// `4 + 12 n`): the text before the first ` bytes`, after its last `(` or `=`; `None` when
/// that is not a sum of products of numbers, `k`, `K`, `D`, `B`, `n` and parentheses.
pub fn memory_formula(declared: &str) -> Option<String> {
    let head = &declared[..declared.find(" bytes")?];
    // The whole head, or what follows one of its `(` or `=` (a formula in words, `"4K+2
    // words in Table 1 ... (16K + 8"`, gives its part in bytes): the first that parses.
    let starts = std::iter::once(0).chain(head.match_indices(['(', '=']).map(|(i, _)| i + 1));
    let one = Vars {
        k: 1.0,
        fixed_k: 1.0,
        d: 1.0,
        b: 1.0,
        n: 1.0,
    };
    starts
        .map(|i| head[i..].trim())
        .find(|f| eval(f, &one).is_some())
        .map(str::to_string)
}

/// Evaluates a formula of [`memory_formula`].
pub fn eval(f: &str, v: &Vars) -> Option<f64> {
    let tokens = tokens(f)?;
    let mut pos = 0;
    let x = sum(&tokens, &mut pos, v)?;
    (pos == tokens.len()).then_some(x)
}

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Num(f64),
    Var(char),
    Plus,
    Open,
    Close,
}

fn tokens(f: &str) -> Option<Vec<Tok>> {
    let mut out = Vec::new();
    let mut chars = f.chars().peekable();
    while let Some(&c) = chars.peek() {
        match c {
            ' ' => {
                chars.next();
            }
            '0'..='9' | '.' => {
                let mut s = String::new();
                while let Some(&d) = chars.peek().filter(|d| d.is_ascii_digit() || **d == '.') {
                    s.push(d);
                    chars.next();
                }
                out.push(Tok::Num(s.parse().ok()?));
            }
            'k' | 'K' | 'D' | 'B' | 'n' => {
                chars.next();
                // A variable is one letter: "kb" is a word, not a formula.
                if chars.peek().is_some_and(|d| d.is_alphabetic()) {
                    return None;
                }
                out.push(Tok::Var(c));
            }
            '+' => {
                chars.next();
                out.push(Tok::Plus);
            }
            '(' => {
                chars.next();
                out.push(Tok::Open);
            }
            ')' => {
                chars.next();
                out.push(Tok::Close);
            }
            _ => return None,
        }
    }
    (!out.is_empty()).then_some(out)
}

fn sum(t: &[Tok], pos: &mut usize, v: &Vars) -> Option<f64> {
    let mut x = product(t, pos, v)?;
    while t.get(*pos) == Some(&Tok::Plus) {
        *pos += 1;
        x += product(t, pos, v)?;
    }
    Some(x)
}

fn product(t: &[Tok], pos: &mut usize, v: &Vars) -> Option<f64> {
    let mut x = factor(t, pos, v)?;
    while matches!(t.get(*pos), Some(Tok::Num(_) | Tok::Var(_) | Tok::Open)) {
        x *= factor(t, pos, v)?;
    }
    Some(x)
}

fn factor(t: &[Tok], pos: &mut usize, v: &Vars) -> Option<f64> {
    let x = match t.get(*pos)? {
        Tok::Num(x) => *x,
        Tok::Var('k') => v.k,
        Tok::Var('K') => v.fixed_k,
        Tok::Var('D') => v.d,
        Tok::Var('B') => v.b,
        Tok::Var(_) => v.n,
        Tok::Open => {
            *pos += 1;
            let x = sum(t, pos, v)?;
            if t.get(*pos) != Some(&Tok::Close) {
                return None;
            }
            x
        }
        _ => return None,
    };
    *pos += 1;
    Some(x)
}

/// Geometry passes of a declaration that does not depend on the scene (`"2 geometry
/// (count, store) + 3 full-screen"` gives 2); `None` when it does (per layer or iteration,
/// ranges such as "1 to k").
pub fn fixed_geometry_passes(declared: &str) -> Option<u32> {
    // Parenthesised remarks are not passes, but for the count pass of a pool sized exactly
    // (`"(+1 count pass when the pool is sized exactly)"`), which the default parameters
    // run.
    let mut plain = String::new();
    let mut remark = String::new();
    let mut extra = 0;
    let mut depth = 0;
    for c in declared.chars() {
        match c {
            '(' => depth += 1,
            ')' => {
                depth -= 1;
                if let Some((_, after)) = remark.split_once('+') {
                    let mut w = after.split_whitespace();
                    if let (Some(n), true) = (
                        w.next(),
                        after.contains("pass when the pool is sized exactly"),
                    ) {
                        extra += n.parse::<u32>().ok()?;
                    }
                }
                remark.clear();
            }
            _ if depth == 0 => plain.push(c),
            _ => remark.push(c),
        }
    }
    if plain.contains(" per ") || plain.contains(" to ") || plain.contains(';') {
        return None;
    }
    let mut total = 0;
    for term in plain.split('+') {
        let mut words = term.split_whitespace();
        if let (Some(n), Some("geometry")) = (words.next(), words.next()) {
            total += n.parse::<u32>().ok()?;
        }
    }
    Some(total + extra)
}

/// Fragments an algorithm keeps of one depth layer (Table 1's robustness column): one for
/// the peelers that peel a depth at a time and the bucket schemes (which route equal depths
/// to one bucket); K for the fixed-size buffers of the z-fighting free variants and SRAB's
/// samples; all of them otherwise.
pub fn per_layer(name: &str) -> Option<u32> {
    match name {
        "f2b" | "dual" | "bdp" | "bdp2" | "adp" => Some(1),
        "srab" | "f2b-fab" | "f2b-kb" | "f2b-kb-atomic" | "dual-fab" | "dual-kb" => Some(FIXED_K),
        _ => None,
    }
}

/// R_h of Table 1 on a stack of `c` coplanar fragments per pixel, in the oracle's measure
/// (fragments kept over fragments to keep: all `c`, or the `min(k, c)` nearest), with its
/// formula.
pub fn rh_formula(info: &AlgoInfo, k: u32, c: u32) -> (String, f64) {
    let want = match info.capacity {
        Capacity::KNearest => k.min(c),
        Capacity::All => c,
        // Counts, nearest surfaces and images keep what they should by construction.
        _ => return ("1".into(), 1.0),
    };
    let want_text = if info.capacity == Capacity::KNearest {
        "min(k, C)"
    } else {
        "C"
    };
    match per_layer(info.name) {
        Some(1) => (format!("1 / {want_text}"), 1.0 / f64::from(want)),
        Some(cap) => (
            format!("min(K, C) / {want_text}"),
            f64::from(cap.min(c).min(want)) / f64::from(want),
        ),
        None => ("1".into(), 1.0),
    }
}

/// The row of one algorithm.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Row {
    pub algo: String,
    pub family: String,
    pub memory_declared: String,
    pub memory_formula: Option<String>,
    pub memory_formula_bytes: Option<f64>,
    pub memory_measured_bytes: f64,
    pub passes_declared: String,
    pub geometry_passes_formula: Option<u32>,
    pub geometry_passes_measured: u32,
    pub fullscreen_passes_measured: u32,
    pub rh_formula: String,
    pub rh_formula_value: f64,
    pub rh_measured: f64,
}

/// Measures Table 1 on `coplanar-stack:C` at `size` x `size` (ordered executor, so the
/// table is the same on every machine but for the time).
pub fn measure(size: u32, k: u32, progress: &dyn Progress) -> Result<Vec<Row>, ReportError> {
    let scene = format!("coplanar-stack:{COPLANAR}");
    let mut spec = RunSpec::new(SceneSpec::Builtin(scene.clone()), "truth");
    spec.width = size;
    spec.height = size;
    spec.params.k = k;
    // Ordered, as the doc says: under `parallel` the hazard-prone counters (count-plain)
    // race on the coplanar stack, and R_h would depend on the threads' timing.
    spec.exec.mode = fragrace_emu::ExecMode::Ordered;
    let loaded = ctx(run::load(&spec), || scene.clone())?;
    let truth = ctx(run::truth(&spec, &loaded), || format!("{scene}: the truth"))?;
    let mut rows = Vec::new();
    for algo in fragrace_kernels::algorithms() {
        let info = algo.info();
        progress.step(&format!("depth-fighting: Table 1, {}", info.name));
        let mut s = spec.clone();
        s.algo = info.name.to_string();
        let c = ctx(run::check_with(&s, &loaded, &truth), || {
            format!("{} on {scene}", info.name)
        })?;
        let pixels = f64::from(size) * f64::from(size);
        let p = Params::default();
        let vars = Vars {
            k: f64::from(k),
            fixed_k: f64::from(FIXED_K),
            d: f64::from(p.fab_capacity),
            b: f64::from(p.buckets),
            n: c.metrics.generated as f64 / pixels,
        };
        let formula = memory_formula(info.memory);
        let (rh_text, rh_value) = rh_formula(&info, k, COPLANAR);
        let stats = &c.rendered.result.report.stats;
        rows.push(Row {
            algo: info.name.into(),
            family: info.family.into(),
            memory_declared: info.memory.into(),
            memory_formula_bytes: formula.as_deref().and_then(|f| eval(f, &vars)),
            memory_formula: formula,
            memory_measured_bytes: c.rendered.result.storage_bytes as f64 / pixels,
            passes_declared: info.passes.into(),
            geometry_passes_formula: fixed_geometry_passes(info.passes),
            geometry_passes_measured: stats.geometry_passes,
            fullscreen_passes_measured: stats.fullscreen_passes,
            rh_formula: rh_text,
            rh_formula_value: rh_value,
            rh_measured: c.metrics.robustness,
        });
    }
    Ok(rows)
}

/// A declaration of passes without its remarks: the parenthesised ones and what follows
/// its first `;` or `, ` (the whole text: `fragrace list`).
pub fn short(declared: &str) -> String {
    let mut plain = String::new();
    let mut depth = 0;
    for c in declared.chars() {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            _ if depth == 0 => plain.push(c),
            _ => {}
        }
    }
    let end = [plain.find(';'), plain.find(", ")]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(plain.len());
    plain[..end]
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

fn num(x: Option<f64>) -> Value {
    x.map_or(Value::Null, |x| json!((x * 1000.0).round() / 1000.0))
}

/// The section.
pub fn section(cfg: &PaperConfig, progress: &dyn Progress) -> Result<Section, ReportError> {
    let (size, k) = if cfg.quick { (64, 8) } else { (256, 8) };
    let rows = measure(size, k, progress)?;
    let mut s = Section::new(
        Paper::DepthFighting,
        "Depth-fighting: Table 1 against its formulas",
    );
    s.text.push(format!(
        "Every algorithm on coplanar-stack:{COPLANAR} ({COPLANAR} quads at one depth over \
         each covered pixel), {size}x{size}, k = {k}, ordered executor. Memory: the formula \
         each algorithm declares (fragrace list), evaluated with k = {k}, K = {FIXED_K}, \
         D = FAB slots, B = buckets and n = fragments per pixel of this image, against the \
         bytes it allocated per pixel. A difference is memory the formula leaves out (the \
         declarations name it: resolve targets, counters of the invariants). Passes: the \
         declared geometry passes where they do not depend on the scene. R_h: fragments \
         kept over fragments to keep (all C, or the min(k, C) nearest), against Table 1's \
         robustness column for C = {COPLANAR} coplanar fragments."
    ));
    let columns = [
        "algorithm",
        "family",
        "memory formula (bytes/pixel)",
        "formula value",
        "measured",
        "difference",
        "geometry passes (declared; remarks in fragrace list)",
        "measured geometry",
        "difference",
        "measured full-screen",
        "R_h formula",
        "formula value",
        "measured R_h",
        "difference",
    ];
    let table_rows = rows
        .iter()
        .map(|r| {
            let mem_diff = r.memory_formula_bytes.map(|f| r.memory_measured_bytes - f);
            vec![
                json!(r.algo),
                json!(r.family),
                json!(r
                    .memory_formula
                    .clone()
                    .unwrap_or_else(|| format!("in words: {}", r.memory_declared))),
                num(r.memory_formula_bytes),
                num(Some(r.memory_measured_bytes)),
                num(mem_diff),
                r.geometry_passes_formula
                    .map_or_else(|| json!(short(&r.passes_declared)), |g| json!(g)),
                json!(r.geometry_passes_measured),
                r.geometry_passes_formula.map_or(Value::Null, |g| {
                    json!(i64::from(r.geometry_passes_measured) - i64::from(g))
                }),
                json!(r.fullscreen_passes_measured),
                json!(r.rh_formula),
                num(Some(r.rh_formula_value)),
                num(Some(r.rh_measured)),
                num(Some(r.rh_measured - r.rh_formula_value)),
            ]
        })
        .collect();
    s.tables.push(Table {
        id: "table1-depth-fighting".into(),
        title: format!(
            "Table 1: memory per pixel, passes and R_h on coplanar-stack:{COPLANAR}, formula against measurement"
        ),
        caption: "Formula, measured value and difference side by side; an empty difference: \
                  the declaration is in words or depends on the scene."
            .into(),
        columns: columns.iter().map(|c| c.to_string()).collect(),
        rows: table_rows,
        command: cfg.command(Paper::DepthFighting),
    });
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formulas_parse_and_evaluate() {
        let v = Vars {
            k: 8.0,
            fixed_k: 8.0,
            d: 64.0,
            b: 5.0,
            n: 2.0,
        };
        let f = |s| memory_formula(s).and_then(|f| eval(&f, &v));
        assert_eq!(f("4 + 12 n bytes (head; depth)"), Some(28.0));
        assert_eq!(f("32 (k + 1) + 8 bytes (k core records)"), Some(296.0));
        assert_eq!(f("8k + 8 bytes (k depth+id slots)"), Some(72.0));
        assert_eq!(f("140 bytes: 128 of targets"), Some(140.0));
        assert_eq!(
            f("4K+2 words in Table 1 (16K + 8 bytes, K = 8); here = 12K bytes"),
            Some(136.0)
        );
        assert_eq!(f("24 bytes of targets"), Some(24.0));
        assert_eq!(f("no formula here"), None);
    }

    #[test]
    fn fixed_passes() {
        assert_eq!(
            fixed_geometry_passes("2 geometry (count, store) + 3 full-screen"),
            Some(2)
        );
        assert_eq!(
            fixed_geometry_passes("1 geometry per layer (at most k)"),
            None
        );
        assert_eq!(
            fixed_geometry_passes("1 geometry (depth range) + 2 geometry"),
            Some(3)
        );
        assert_eq!(
            fixed_geometry_passes(
                "1 geometry (+1 count pass when the pool is sized exactly) + 1 full-screen"
            ),
            Some(2)
        );
    }
}
