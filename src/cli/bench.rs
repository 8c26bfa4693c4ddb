//! `fragrace bench`: frames timed as the llvmpipe peer times them.

use super::error::{CliError, OptionError};
use super::memory::{merge, within_budget};
use super::options::RunOptions;
use super::progress::progress;
use crate::run;

/// The options of `bench`: a run, timed over frames.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchOptions {
    #[command(flatten)]
    pub run: RunOptions,
    /// Frames to time (the median is reported).
    #[arg(long, default_value_t = 10)]
    pub frames: usize,
    /// Frames run before the timed ones.
    #[arg(long, default_value_t = 2)]
    pub warmup: usize,
    /// Also measure the machine's floor under the frame (`--algo count` only): its atomic
    /// adds alone on the same threads, and with the allocation of a zeroed buffer.
    #[arg(long)]
    pub floor: bool,
}

/// `bench`: the frames' median time, where it goes and the storage per fragment and pixel.
pub fn cmd_bench(a: &BenchOptions, given: &[String]) -> Result<(), CliError> {
    let spec = a.run.spec(given)?;
    crate::validate::at_least_one("frames", a.frames as u64)?;
    // The floor replays `count`'s operation (one atomic add per fragment); other
    // algorithms do other things per fragment.
    if a.floor && spec.algo != "count" {
        return Err(OptionError::FloorNotCount {
            algo: spec.algo.clone(),
        }
        .into());
    }
    let loaded = run::load(&spec)?;
    let memory = within_budget(&spec, &loaded, false, a.run.memory_limit.as_deref())?;
    // Progress on a terminal (nothing when piped), drawn between frames only: no ticking
    // thread drawing while a frame is timed.
    let bar = progress((a.warmup + a.frames) as u64, "warm-up frames");
    bar.disable_steady_tick();
    for _ in 0..a.warmup {
        run::render(&spec, &loaded)?;
        bar.inc(1);
    }
    bar.set_message("frames");
    // A frame is what the llvmpipe peer times as one (clears, passes, resolve); the
    // self-checks that read whole buffers back run after it, timed apart (the peer checks
    // untimed). Every frame is checked.
    let mut times = Vec::new();
    let mut pass_times = Vec::new();
    let mut check_times = Vec::new();
    let mut checked_times = Vec::new();
    let mut imbalance_times = Vec::new();
    // Per pass (by position in the frame), and the frame's time outside its passes
    // (allocation and clearing of buffers, readback, host work).
    let mut phase_times: Vec<Vec<f64>> = Vec::new();
    let mut outside_times = Vec::new();
    // Every frame in run order (its time and its passes'), for a reader looking at the
    // spread rather than the median.
    let mut in_order = Vec::new();
    // Hazard-prone algorithms may fail a check under real races: reported, not fatal.
    let mut failed_checks = 0;
    let mut last = None;
    for _ in 0..a.frames {
        // The previous frame's buffers are freed first, so that the allocator hands the
        // same memory to this frame, as a renderer reuses its buffers from frame to frame
        // (and as the llvmpipe peer clears and reuses one storage buffer).
        drop(last.take());
        let r = run::render(&spec, &loaded)?;
        failed_checks += r.result.checks.iter().filter(|c| !c.passed).count();
        times.push(r.wall_ms);
        check_times.push(r.check_ms);
        checked_times.push(r.wall_ms + r.check_ms);
        pass_times.push(r.result.report.wall.as_secs_f64() * 1e3);
        imbalance_times.push(r.result.report.imbalance.as_secs_f64() * 1e3);
        let passes = &r.result.report.passes;
        phase_times.resize_with(phase_times.len().max(passes.len()), Vec::new);
        for (times, p) in phase_times.iter_mut().zip(passes) {
            times.push(p.wall.as_secs_f64() * 1e3);
        }
        outside_times.push(r.wall_ms - r.result.report.wall.as_secs_f64() * 1e3);
        in_order.push(serde_json::json!({
            "ms": r.wall_ms,
            "passes_ms": passes.iter().map(|p| p.wall.as_secs_f64() * 1e3).collect::<Vec<_>>(),
        }));
        last = Some(r);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let r = last.expect("one frame");
    let ms = crate::floor::median(&mut times);
    let check_ms = crate::floor::median(&mut check_times);
    let checked_ms = crate::floor::median(&mut checked_times);
    // The passes alone (transform, binning, shading, fixed function), without buffer
    // allocation and clears.
    let pass_ms = crate::floor::median(&mut pass_times);
    // Threads waiting for the last one at the end of shading, summed over threads.
    let imbalance_ms = crate::floor::median(&mut imbalance_times);
    let outside_ms = crate::floor::median(&mut outside_times);
    let phases: Vec<(String, f64)> = r
        .result
        .report
        .passes
        .iter()
        .zip(phase_times.iter_mut())
        .map(|(p, times)| {
            let kind = if p.full_screen {
                "full-screen"
            } else {
                "geometry"
            };
            (
                format!("{} ({kind})", p.kernel),
                crate::floor::median(times),
            )
        })
        .collect();
    let stats = &r.result.report.stats;
    // The storage the algorithm allocated (buffers and render targets), per fragment
    // rasterized and per pixel.
    let storage = r.result.storage_bytes as f64;
    let pixels = f64::from(spec.width) * f64::from(spec.height);
    let bytes_per_fragment = storage / (stats.fragments_generated.max(1) as f64);
    let bytes_per_pixel = storage / pixels.max(1.0);
    let tris = loaded.scene.mesh.triangle_count() as f64 * stats.geometry_passes.max(1) as f64;
    let floor = if a.floor {
        let counts = r
            .result
            .counts
            .as_deref()
            .ok_or_else(|| OptionError::FloorWithoutCounts {
                algo: spec.algo.clone(),
            })?;
        let cfg = crate::floor::FloorConfig {
            counts,
            width: spec.width,
            height: spec.height,
            tile: crate::emu::raster::effective_tile_size(
                crate::emu::raster::RasterState::default().tile_size,
            ),
            threads: spec.exec.threads,
            frames: a.frames,
        };
        Some(crate::floor::count_floor(&cfg).ok_or(CliError::Floor)?)
    } else {
        None
    };
    let mut v = serde_json::json!({
        "algo": spec.algo,
        "scene": spec.scene.name(),
        "triangles": loaded.scene.mesh.triangle_count(),
        "width": spec.width, "height": spec.height,
        "exec": spec.exec.mode.name(),
        "threads": spec.exec.threads,
        "frames": times.len(),
        "median_ms": ms,
        "passes_median_ms": pass_ms,
        "imbalance_median_ms": imbalance_ms,
        "check_median_ms": check_ms,
        "checked_median_ms": checked_ms,
        "failed_checks": failed_checks,
        "min_ms": times.first(),
        "max_ms": times.last(),
        "fragments": stats.fragments_generated,
        "fragments_per_s": stats.fragments_generated as f64 / (ms / 1e3),
        "triangles_per_s": tris / (ms / 1e3),
        "steps": stats.steps,
        "steps_per_s": stats.steps as f64 / (ms / 1e3),
        "storage_bytes": r.result.storage_bytes,
        "bytes_per_fragment": bytes_per_fragment,
        "bytes_per_pixel": bytes_per_pixel,
        "outside_passes_median_ms": outside_ms,
        "phases": phases
            .iter()
            .map(|(pass, ms)| serde_json::json!({ "pass": pass, "median_ms": ms }))
            .collect::<Vec<_>>(),
        "frames_in_order": in_order,
    });
    merge(&mut v, &memory);
    v["peak_rss_bytes"] = serde_json::json!(crate::budget::peak_rss());
    if let Some(f) = floor {
        v["floor_atomics_ms"] = f.atomics_ms.into();
        v["floor_frame_ms"] = f.frame_ms.into();
    }
    if a.run.json {
        println!("{v}");
    } else {
        println!(
            "{} on {} ({} triangles) {}x{}, {} with {} threads: median {:.2} ms over {} frames (min {:.2}, max {:.2}); passes alone {:.2} ms; self-checks after it {:.2} ms (frame and checks {:.2} ms)\n  {:.1} M fragments/s, {:.1} M triangles/s, {:.2} M steps/s",
            spec.algo, spec.scene.name(), loaded.scene.mesh.triangle_count(), spec.width, spec.height, spec.exec.mode.name(), spec.exec.threads,
            ms, times.len(), times[0], times[times.len() - 1], pass_ms, check_ms, checked_ms,
            stats.fragments_generated as f64 / (ms / 1e3) / 1e6, tris / (ms / 1e3) / 1e6, stats.steps as f64 / (ms / 1e3) / 1e6
        );
        println!(
            "  storage {:.1} bytes per fragment, {:.1} bytes per pixel",
            bytes_per_fragment, bytes_per_pixel
        );
        let phases_line: Vec<String> = phases
            .iter()
            .map(|(pass, ms)| format!("{pass} {ms:.2} ms"))
            .collect();
        println!(
            "  where the frame goes (medians): outside the passes (buffers, clears, readback) {outside_ms:.2} ms; {}",
            phases_line.join("; ")
        );
        if spec.exec.threads > 1 {
            println!(
                "  threads idle at the end of shading, waiting for the last one: {imbalance_ms:.3} ms (median, summed over threads)"
            );
        }
        if failed_checks > 0 {
            println!(
                "  {failed_checks} failed checks over the frames (see `{} render`)",
                run::CLI
            );
        }
        if let Some(f) = floor {
            println!(
                "  floor: the frame's {} atomic adds alone {:.2} ms; with a fresh zeroed buffer {:.2} ms",
                stats.fragments_generated, f.atomics_ms, f.frame_ms
            );
        }
    }
    Ok(())
}
