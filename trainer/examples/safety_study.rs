//! The safety study (issue 41 §6) of a problem file at scale, without the pipeline's other
//! stages: the problem as `trainer run` labels it (`pipeline::labelling_problem`), its sampling
//! plan labelled (`trainer::sample`), the regularized sequence net trained as `trainer run`
//! trains it (`trainer::train`; the validation set only gives statistics, so the training set
//! stands in for it), and `study::safety::safety_study` with the generated plant's emulation
//! and that net — what the `closed_loop` stage runs — for `RUNS` nominal closed loops and
//! `MISMATCH` per mismatch scenario and sign. Prints the summaries and each phase's wall time,
//! and writes the study (without the per-run lists) to `OUT`.
//!
//! `cargo run --release -p trainer --example safety_study -- CONFIG RUNS MISMATCH OUT.json`

use std::time::Instant;
use trainer::deploy::safe_emulation::{EmulatedPlant, EmulatedSequenceNet};
use trainer::problem::ProblemConfig;
use trainer::study::safety::{safety_study, ControllerRuns, SafetyGroup};

fn line(name: &str, c: &ControllerRuns, runs: usize) {
    println!(
        "  {name:5}: violating steps {} in {} runs; fallback {:.2} % of steps; no-safe steps {}; \
         median cost ratio {}; converged {}/{runs}",
        c.total_violations,
        c.violating_runs,
        100.0 * c.fallback_share,
        c.no_safe_steps,
        c.median_cost_ratio
            .map_or("-".into(), |v| format!("{v:.4}")),
        c.converged
    );
}

fn group(title: &str, g: &SafetyGroup) {
    let runs = g.safe.runs.len();
    println!(
        "{title} ({runs} runs): MPC hard-feasible starts {}; safe initialised by the MPC {}, \
         the terminal rollout {}, a candidate {}, never {}",
        g.mpc_feasible_starts,
        g.init_mpc,
        g.init_terminal,
        g.init_candidate,
        g.runs_without_safe_sequence
    );
    line("safe", &g.safe, runs);
    if let Some(c) = &g.safe.candidate {
        println!(
            "  safe candidate: checked {}, taken {}, outside U {} (then taken {}), stage \
             violation {}, terminal miss {}, non-finite {}, costlier {} (in X_f {}; rel. excess \
             buckets <=1e-4,1e-3,1e-2,1e-1,more: {:?})",
            c.checked,
            c.taken,
            c.outside_u,
            c.outside_u_taken,
            c.stage_violation,
            c.terminal_miss,
            c.non_finite,
            c.costlier,
            c.costlier_in_xf,
            c.costlier_rel
        );
    }
    line("plain", &g.plain, runs);
    line("mpc", &g.mpc, runs);
    let from_start: Vec<_> = g
        .safe
        .runs
        .iter()
        .filter(|r| r.no_safe_steps == 0)
        .collect();
    let steps: usize = from_start.iter().map(|r| r.steps).sum();
    let fb: usize = from_start.iter().map(|r| r.fallback_steps).sum();
    println!(
        "  safe runs with a safe sequence from step 0: {} runs, {} violating steps, fallback \
         {:.2} % of their steps",
        from_start.len(),
        from_start.iter().map(|r| r.violation_steps).sum::<usize>(),
        100.0 * fb as f64 / steps.max(1) as f64
    );
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() != 5 {
        return Err("usage: safety_study CONFIG RUNS MISMATCH OUT.json".into());
    }
    let base = ProblemConfig::load(std::path::Path::new(&a[1]))?;
    let mut cfg = trainer::pipeline::labelling_problem(&base)?;
    cfg.closed_loop.safety_runs = a[2].parse()?;
    cfg.closed_loop.safety_mismatch_runs = a[3].parse()?;
    let t = Instant::now();
    let dir = std::env::temp_dir().join(format!("safety_study_{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let data = trainer::sample(&cfg, &dir.join("dataset.bin"))?;
    println!(
        "sample: {} states, {:.1} s",
        data.records.len(),
        t.elapsed().as_secs_f64()
    );
    let t = Instant::now();
    let model = trainer::train(&cfg, &data, &data, false)?;
    println!("train: {:.1} s", t.elapsed().as_secs_f64());
    let seq = model.sequence.as_ref().ok_or("no sequence net")?;
    let (plant, g) = EmulatedPlant::new(&base)?;
    let net = EmulatedSequenceNet::new(seq, cfg.ocp.horizon, cfg.system.nu());
    let source = move |x: &[f32]| net.sequence(x);
    let t = Instant::now();
    let mut s = safety_study(&cfg, &plant, (g.invariance(), g.decrease), &source);
    println!("study: {:.1} s", t.elapsed().as_secs_f64());
    println!("choice: {}", s.choice);
    group("nominal", &s.nominal);
    for (k, m) in &s.mismatch {
        group(&format!("mismatch {k}"), m);
    }
    for g in std::iter::once(&mut s.nominal).chain(s.mismatch.values_mut()) {
        for c in [&mut g.safe, &mut g.plain, &mut g.mpc] {
            c.runs.clear();
        }
    }
    std::fs::write(&a[4], serde_json::to_string_pretty(&s)?)?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
