//! `report --paper`: Table 1's formulas hold on a built-in scene, and a quick report of
//! every section writes a page whose every reference exists.

use fragrace::report::{self, depth_fighting, Paper, PaperConfig};

/// R_h measured on the coplanar stack equals Table 1's robustness column for every
/// algorithm; every parsed memory formula is at most the bytes allocated (what it leaves
/// out, the declarations name), and equals them for the algorithms whose declaration is the
/// whole of their memory; fixed geometry passes equal the passes run.
#[test]
fn table1_formulas_hold_on_the_coplanar_stack() {
    let rows = depth_fighting::measure(32, 8, &|_: &str| {}).unwrap();
    assert_eq!(rows.len(), fragrace::kernels::names().len());
    for r in &rows {
        assert!(
            (r.rh_measured - r.rh_formula_value).abs() < 1e-9,
            "{}: R_h {} against the formula {} = {}",
            r.algo,
            r.rh_measured,
            r.rh_formula,
            r.rh_formula_value
        );
        if let Some(g) = r.geometry_passes_formula {
            assert_eq!(r.geometry_passes_measured, g, "{}: geometry passes", r.algo);
        }
    }
    // The algorithms whose declared formula is all they allocate (but for a few bytes of
    // global counters, less than 0.02 bytes per pixel at 32x32).
    for name in [
        "count", "truth", "f2b", "f2b-ll", "f2b-fab", "f2b-kb", "dual-fab", "dual-kb", "dual-ll",
        "bdp", "bdp2", "adp",
    ] {
        let r = rows.iter().find(|r| r.algo == name).unwrap();
        let f = r
            .memory_formula_bytes
            .unwrap_or_else(|| panic!("{name}: no formula"));
        assert!(
            (r.memory_measured_bytes - f).abs() < 0.02,
            "{name}: {} bytes per pixel against the formula {:?} = {f}",
            r.memory_measured_bytes,
            r.memory_formula
        );
    }
    // Every other formula leaves memory out, never counts too much (srab's is Table 1's
    // 4K + 2 words, more than its 12K bytes).
    for r in rows.iter().filter(|r| r.algo != "srab") {
        if let Some(f) = r.memory_formula_bytes {
            assert!(
                r.memory_measured_bytes >= f - 0.02,
                "{}: formula {f} above the measured {}",
                r.algo,
                r.memory_measured_bytes
            );
        }
    }
    // At least three in four declarations are machine-readable formulas.
    let parsed = rows
        .iter()
        .filter(|r| r.memory_formula_bytes.is_some())
        .count();
    assert!(
        parsed * 4 >= rows.len() * 3,
        "{parsed} of {} formulas parsed",
        rows.len()
    );
}

/// The quick report of every section: every file the page references exists, every SVG is
/// a whole SVG document, report.json has every figure's points.
#[test]
fn quick_report_of_every_section_is_complete() {
    let out = std::env::temp_dir().join(format!("fragrace-report-{}", std::process::id()));
    let cfg = PaperConfig {
        papers: Paper::ALL.to_vec(),
        out: out.clone(),
        quick: true,
        models: None,
        threads: 2,
        peer: None,
    };
    let written = report::generate(&cfg, &|_: &str| {}).unwrap();
    let html = std::fs::read_to_string(&written.index).unwrap();
    let mut refs = 0;
    for attr in ["src=\"", "href=\""] {
        for part in html.split(attr).skip(1) {
            let target = &part[..part.find('"').unwrap()];
            if target.starts_with('#') {
                continue;
            }
            assert!(
                !target.contains("://"),
                "the page loads {target} from a network"
            );
            assert!(
                out.join(target).is_file(),
                "the page references {target}, not written"
            );
            refs += 1;
        }
    }
    assert!(refs >= 10, "{refs} references");
    for f in &written.files {
        if f.extension().is_some_and(|e| e == "svg") {
            let svg = std::fs::read_to_string(f).unwrap();
            assert!(
                svg.trim_start().starts_with("<svg") && svg.trim_end().ends_with("</svg>"),
                "{}",
                f.display()
            );
            assert!(
                svg.matches("<text").count() >= 5,
                "{}: axis labels and ticks",
                f.display()
            );
        }
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let figures: Vec<&serde_json::Value> = json["sections"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|s| s["figures"].as_array().unwrap())
        .collect();
    assert!(figures.len() >= 5);
    let mut boxes = 0;
    for f in figures {
        // A line plot's series have points; a box plot's boxes have values.
        let (list, key) = match f.get("series") {
            Some(s) => (s, "points"),
            None => {
                boxes += 1;
                (&f["boxes"], "values")
            }
        };
        let list = list.as_array().unwrap();
        assert!(!list.is_empty(), "{}", f["id"]);
        assert!(
            list.iter().all(|s| !s[key].as_array().unwrap().is_empty()),
            "{}",
            f["id"]
        );
        assert!(f["command"].as_str().unwrap().contains("--paper"));
    }
    assert!(
        boxes >= 1,
        "the hazards section draws EPR distributions as box plots"
    );
    assert!(json["machine"]["cpu"]
        .as_str()
        .is_some_and(|c| !c.is_empty()));
    // The grid of the hazards section: every hazard-prone algorithm under every policy.
    let grid = std::fs::read_to_string(out.join("hazards-grid.csv")).unwrap();
    for p in [
        "random",
        "pct:2",
        "pct:3",
        "warp:32",
        "far-first",
        "parallel",
    ] {
        assert!(
            grid.contains(&format!(",{p},")),
            "{p} missing from the grid"
        );
    }
    // Regenerating one section keeps the others on the page, with their own machine line.
    let again = PaperConfig {
        papers: vec![Paper::Presorted],
        ..cfg
    };
    report::generate(&again, &|_: &str| {}).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let kept: Vec<&str> = json["sections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["paper"].as_str().unwrap())
        .collect();
    assert_eq!(kept.len(), Paper::ALL.len(), "{kept:?}");
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(html.contains("hazards-grid.csv") && html.contains("figure6-epr-views.png"));
    assert!(html.contains("--paper all"), "the page's whole command");
    std::fs::remove_dir_all(&out).ok();
}
