//! The safety study (`trainer::study::safety`, `[closed_loop] safety = true`) end to end on
//! the double integrator (`configs/double_integrator_ode.toml`, robust terminal region), with
//! candidate sources whose outcome is known in advance, so that a wrong count fails:
//!
//! - **a network that only outputs NaN**: every candidate fails the online check. A run whose
//!   start the MPC labels with a sequence that passes the check (or whose terminal rollout
//!   passes it) is initialised by it (step 0 applies its first input) and then falls back at
//!   every later step; a run without one never has a safe sequence (every step `NO_SAFE`). So
//!   Σ fallback = (init_mpc + init_terminal) · (steps − 1),
//!   Σ no-safe = runs_without_safe_sequence · steps, no run initialised by a candidate, and
//!   — the nominal guarantee, the fallback replaying the MPC's plan completed by κ_f — no
//!   violation in every initialised run. The plain network applies Π_U(NaN) =
//!   u_ref = 0: the double integrator coasts, and the runs starting with a velocity do not
//!   converge;
//! - **the terminal controller's f32 rollout** as the candidate (the sequence a perfect
//!   network would give inside X_f): accepted where feasible, so fewer fallbacks than the
//!   NaN network, and no violation in the runs that have a safe sequence from the start;
//! - the MPC's own cost ratio is exactly 1, the JSON has no null, and the result does not
//!   depend on the number of threads;
//! - **the terminal ingredients shared by the MPC and the check** (`[ocp.online_check]`, what
//!   `trainer run` imposes with `safety = true`): every hard optimum's sequence passes the
//!   emulated online check, while without them some do not.

use std::path::{Path, PathBuf};
use trainer::deploy::safe_emulation::EmulatedPlant;
use trainer::problem::ProblemConfig;
use trainer::study::safety::{safety_study, terminal_rollout as rollout, SafetyStudy};

fn config() -> ProblemConfig {
    let root: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut cfg =
        ProblemConfig::load(&root.join("configs").join("double_integrator_ode.toml")).unwrap();
    cfg.closed_loop.steps = 40;
    cfg.closed_loop.safety_runs = 12;
    cfg.closed_loop.safety_mismatch_runs = 0;
    cfg
}

fn run(
    cfg: &ProblemConfig,
    plant: &EmulatedPlant,
    threads: usize,
    source: &(dyn Fn(&[f32]) -> Vec<Vec<f32>> + Sync),
) -> SafetyStudy {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(|| safety_study(cfg, plant, ("proven", "sampled"), source))
}

#[test]
fn a_nan_network_always_falls_back_and_the_counts_say_so() {
    let cfg = config();
    let (plant, _) = EmulatedPlant::new(&cfg).unwrap();
    let (n, nu, steps) = (cfg.ocp.horizon, cfg.system.nu(), cfg.closed_loop.steps);
    let nan = move |_: &[f32]| vec![vec![f32::NAN; nu]; n];
    let s = run(&cfg, &plant, 2, &nan);
    let g = &s.nominal;
    let runs = cfg.closed_loop.safety_runs as u64;
    assert_eq!(g.safe.runs.len() as u64, runs);
    assert_eq!(
        g.init_mpc + g.init_terminal + g.init_candidate + g.runs_without_safe_sequence,
        runs
    );
    assert_eq!(g.init_candidate, 0, "a NaN candidate never initialises");
    // From this X, some starts cannot reach the terminal set within N (no MPC sequence
    // passes the check) and some can: both branches are counted.
    assert!(
        g.init_mpc >= 1 && g.runs_without_safe_sequence >= 1,
        "{g:?}"
    );
    let fallback: usize = g.safe.runs.iter().map(|r| r.fallback_steps).sum();
    let init = g.init_mpc + g.init_terminal;
    assert_eq!(fallback as u64, init * (steps as u64 - 1));
    assert_eq!(
        g.safe.no_safe_steps,
        g.runs_without_safe_sequence * steps as u64
    );
    let share = fallback as f64 / (runs as f64 * steps as f64);
    assert!((g.safe.fallback_share - share).abs() < 1e-12);
    for r in g.safe.runs.iter().filter(|r| r.fallback_steps > 0) {
        assert_eq!(r.violation_steps, 0, "{r:?}");
    }
    assert_eq!(g.mpc.median_cost_ratio, Some(1.0));
    assert_eq!(g.mpc.fallback_share, 0.0);
    assert!(
        g.plain.converged < runs,
        "u = 0 does not stop the double integrator"
    );
    let json = serde_json::to_string(&s).unwrap();
    assert!(!json.contains("null"), "{json}");
    for key in [
        "\"safe\":",
        "\"plain\":",
        "\"mpc\":",
        "\"violation_steps\":",
        "\"fallback_steps\":",
        "\"converged\":",
        "\"cost\":",
    ] {
        assert!(json.contains(key), "{key}");
    }
    assert!(s
        .guarantee
        .contains("deterministic for the nominal model: constraint satisfaction and convergence"));
    let back: SafetyStudy = serde_json::from_str(&json).unwrap();
    assert_eq!(back, s);
    // Thread count does not matter.
    assert_eq!(run(&cfg, &plant, 1, &nan), s);
}

/// The terminal controller's rollout over `n` steps as a candidate source.
fn terminal_rollout(p: &EmulatedPlant, n: usize) -> impl Fn(&[f32]) -> Vec<Vec<f32>> + Sync + '_ {
    move |x: &[f32]| rollout(p, n, x)
}

/// The MPC's sequence at each of the study's first starts handed to the emulated
/// `init_with`: (hard optima, of which pass).
fn mpc_passes(cfg: &ProblemConfig, plant: &EmulatedPlant, starts: u64) -> (usize, usize) {
    use trainer::deploy::safe_emulation::SafeEmulation;
    use trainer::mpc::sqp::SqpStatus;
    let (nu, n) = (cfg.system.nu(), cfg.ocp.horizon);
    let mut law = trainer::mpc::law::MpcLaw::new(cfg);
    let (mut hard, mut pass) = (0, 0);
    for i in 0..starts {
        let x0 = trainer::study::safety::start(cfg, i);
        let (l, _) = law.solve(&x0, None);
        if l.status != SqpStatus::Converged {
            continue;
        }
        hard += 1;
        let rows: Vec<Vec<f32>> = l
            .seq
            .chunks(nu)
            .map(|r| r.iter().map(|v| *v as f32).collect())
            .collect();
        let x32: Vec<f32> = x0.iter().map(|v| *v as f32).collect();
        pass += usize::from(
            SafeEmulation::new(plant, n)
                .init_with(&x32, &rows)
                .is_some(),
        );
    }
    (hard, pass)
}

/// Hose et al.'s consistency: with the check's terminal set, terminal cost and margins imposed
/// on the MPC (`pipeline::labelling_problem`), the MPC's sequence passes the device's check at
/// every start where the MPC is (hard) feasible; the problem file's own OCP, without them,
/// fails it at some of the same starts — so the count can fail. The device's plant is the same
/// for both (generated from the problem without the block).
#[test]
fn the_mpc_sequence_passes_the_online_check_with_the_shared_terminal_ingredients() {
    let mut base = config();
    base.training.outputs = trainer::problem::Outputs::Sequence;
    base.closed_loop.safety = true;
    let cfg = trainer::pipeline::labelling_problem(&base).unwrap();
    let c = cfg.ocp.online_check.as_ref().expect("the block is filled");
    let (plant, g) = EmulatedPlant::new(&base).unwrap();
    assert!(c.alpha < g.terminal.alpha() * (1.0 - f64::from(plant.margins.1)));
    let (plant2, _) = EmulatedPlant::new(&cfg).unwrap();
    assert_eq!(
        format!("{plant:?}"),
        format!("{plant2:?}"),
        "the check is unchanged"
    );
    let (hard, pass) = mpc_passes(&cfg, &plant, 24);
    assert!(hard >= 6, "{hard} hard optima");
    assert_eq!(pass, hard);
    base.closed_loop.safety_terminal = false;
    let same = trainer::pipeline::labelling_problem(&base).unwrap();
    assert!(same.ocp.online_check.is_none());
    let (hard, pass) = mpc_passes(&same, &plant, 24);
    assert!(pass < hard, "{pass} of {hard}");
}

#[test]
fn the_terminal_controller_as_network_is_accepted() {
    let cfg = config();
    let (plant, _) = EmulatedPlant::new(&cfg).unwrap();
    let rollout = terminal_rollout(&plant, cfg.ocp.horizon);
    let s = run(&cfg, &plant, 2, &rollout);
    let g = &s.nominal;
    // Nothing is guaranteed before a safe sequence exists (NO_SAFE steps apply the
    // candidate's first input); once one exists from the start, no violation.
    for r in g.safe.runs.iter().filter(|r| r.no_safe_steps == 0) {
        assert_eq!(r.violation_steps, 0, "{r:?}");
    }
    assert!(g.safe.runs.iter().any(|r| r.no_safe_steps == 0));
    // The saturated terminal controller is feasible from most starts of this X: candidates
    // are taken, so fallbacks stay below half of the NaN network's bound (every step but one).
    let steps = cfg.closed_loop.steps as f64;
    assert!(g.safe.fallback_share < (steps - 1.0) / steps * 0.5, "{g:?}");
    assert!(g.safe.runs.iter().any(|r| r.fallback_steps == 0));
}

/// The `closed_loop.json` contract of issue 41 §6, read as plain JSON: with the study, the
/// top-level `safe`, `plain`, `mpc` are lists of the study's runs from the same starts, each
/// with `violation_steps`, `fallback_steps`, `cost`, `converged` (and `steps`), `safety`
/// holds the summaries without repeating the lists, and the ordinary study's MPC runs are
/// under `mpc_nominal`; the file reads back to the same value, and without the study it is
/// the plain map of runs as before (the ordinary runs under `mpc`).
#[test]
fn closed_loop_json_has_the_issue_keys() {
    use trainer::mpc::law::MpcLaw;
    use trainer::study::closed_loop::{simulate, Controller, SimSettings};
    use trainer::study::scenarios::{ClosedLoop, ClosedLoopFile, ORDINARY_MPC_KEY};
    let mut cfg = config();
    cfg.closed_loop.safety_runs = 5;
    cfg.closed_loop.steps = 10;
    let (plant, _) = EmulatedPlant::new(&cfg).unwrap();
    let rollout = terminal_rollout(&plant, cfg.ocp.horizon);
    let study = run(&cfg, &plant, 2, &rollout);
    let sim = SimSettings {
        steps: cfg.closed_loop.steps,
        noise: vec![],
        seed: 0,
        mass_mismatch: 0.0,
        mismatch_parameter: None,
        disturbance: Default::default(),
    };
    let mut law = MpcLaw::new(&cfg);
    let ordinary = simulate(&cfg, &mut law, &Controller::Mpc, &[0.5, 0.0], &sim);
    let mut runs = ClosedLoop::new();
    runs.insert("mpc".into(), vec![ordinary.clone()]);
    runs.insert("mpc_noise".into(), vec![ordinary.clone()]);

    // Without the study: the map of runs, `mpc` the ordinary runs.
    let plain_file = ClosedLoopFile {
        safety: None,
        runs: runs.clone(),
    };
    let text = serde_json::to_string(&plain_file).unwrap();
    assert_eq!(text, serde_json::to_string(&runs).unwrap());
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(v.get("safe").is_none() && v.get("safety").is_none());
    assert!(v["mpc"][0].get("x0").is_some());
    assert_eq!(
        serde_json::from_str::<ClosedLoopFile>(&text).unwrap(),
        plain_file
    );

    // With it.
    let file = ClosedLoopFile {
        safety: Some(study.clone()),
        runs,
    };
    let text = serde_json::to_string(&file).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let m = v.as_object().unwrap();
    let keys: Vec<&str> = m.keys().map(|k| k.as_str()).collect();
    assert_eq!(
        keys,
        [
            "mpc",
            "mpc_noise",
            ORDINARY_MPC_KEY,
            "plain",
            "safe",
            "safety"
        ]
    );
    for (key, mine) in [
        ("safe", &study.nominal.safe.runs),
        ("plain", &study.nominal.plain.runs),
        ("mpc", &study.nominal.mpc.runs),
    ] {
        let list = m[key].as_array().unwrap();
        assert_eq!(list.len(), cfg.closed_loop.safety_runs, "{key}");
        for (r, mine) in list.iter().zip(mine) {
            assert_eq!(
                r["violation_steps"].as_u64(),
                Some(mine.violation_steps as u64)
            );
            assert_eq!(
                r["fallback_steps"].as_u64(),
                Some(mine.fallback_steps as u64)
            );
            assert_eq!(r["cost"].as_f64(), Some(mine.cost));
            assert_eq!(r["converged"].as_bool(), Some(mine.converged));
            assert_eq!(r["steps"].as_u64(), Some(cfg.closed_loop.steps as u64));
        }
    }
    // The MPC's own runs carry no fallback; the safe runs' fallbacks are the summary's.
    assert!(m["mpc"]
        .as_array()
        .unwrap()
        .iter()
        .all(|r| r["fallback_steps"] == 0));
    let fb: u64 = m["safe"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["fallback_steps"].as_u64().unwrap())
        .sum();
    let share = m["safety"]["safe"]["fallback_share"].as_f64().unwrap();
    let total = (cfg.closed_loop.safety_runs * cfg.closed_loop.steps) as f64;
    assert!((share - fb as f64 / total).abs() < 1e-15);
    // The summaries do not repeat the lists; the ordinary runs kept every field.
    assert!(m["safety"]["safe"].get("runs").is_none());
    assert!(m[ORDINARY_MPC_KEY][0].get("x0").is_some());
    assert!(m["mpc_noise"][0].get("x0").is_some());
    assert!(!text.contains("null"));
    // Round trip: in memory nothing moved.
    let back: ClosedLoopFile = serde_json::from_str(&text).unwrap();
    assert_eq!(back, file);
    assert_eq!(back.runs["mpc"], vec![ordinary]);

    // A file of the first layout (the study's lists nested under `safety`) still reads.
    let mut old = serde_json::to_value(&file.runs).unwrap();
    old["safety"] = serde_json::to_value(&study).unwrap();
    let back: ClosedLoopFile = serde_json::from_value(old).unwrap();
    assert_eq!(back, file);
}
