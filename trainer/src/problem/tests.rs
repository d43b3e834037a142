//! Problem files: the shipped files parse and validate, errors name the key at fault,
//! the problem hash tracks the labels only.

use super::*;

const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/");

#[test]
fn shipped_configs_parse_and_validate() {
    for f in [
        "pendulum.toml",
        "cartpole.toml",
        "double_integrator.toml",
        "pendulum_robust.toml",
        "pendulum_ode.toml",
        "double_integrator_ode.toml",
    ] {
        let path = std::path::PathBuf::from(DIR).join(f);
        ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{f}: {e}"));
    }
    let d = ProblemConfig::default();
    assert_eq!(d.name, "pendulum");
    assert_eq!(d, ProblemConfig::from_toml_str(PENDULUM_TOML, "x").unwrap());
    assert_eq!(d.ocp.horizon, 20);
    assert_eq!(d.sampling.counts, vec![35, 10]);
}

fn err_key(edit: impl Fn(&mut ProblemConfig)) -> String {
    let mut c = ProblemConfig::default();
    edit(&mut c);
    match c.validate() {
        Err(ConfigError::Invalid { key, .. }) => key,
        other => panic!("expected Invalid, got {other:?}"),
    }
}

#[test]
fn a_problem_file_with_an_invalid_setting_is_named() {
    let text = PENDULUM_TOML.replacen("horizon = 20", "horizon = 0", 1);
    assert_ne!(text, PENDULUM_TOML);
    let e = ProblemConfig::from_toml_str(&text, "configs/mine.toml").unwrap_err();
    assert!(matches!(&e, ConfigError::Invalid { key, .. } if key == "ocp.horizon"));
    assert!(
        e.to_string()
            .starts_with("problem file configs/mine.toml: invalid setting `ocp.horizon`"),
        "{e}"
    );
    // A config built in code has no file to name.
    let mut c = ProblemConfig::default();
    c.ocp.horizon = 0;
    assert!(c
        .validate()
        .unwrap_err()
        .to_string()
        .starts_with("invalid setting `ocp.horizon`"));
}

#[test]
fn validation_names_the_key_at_fault() {
    assert_eq!(err_key(|c| c.ocp.horizon = 0), "ocp.horizon");
    // `validation_n = 0` must be refused: accepted, it hangs the plots stage on R² = NaN.
    for n in [0, 1] {
        assert_eq!(
            err_key(|c| c.training.validation_n = n),
            "training.validation_n"
        );
    }
    assert_eq!(
        err_key(|c| c.ocp.q = MatrixSpec::Diagonal(vec![1.0])),
        "ocp.q"
    );
    assert_eq!(
        err_key(|c| c.ocp.q = MatrixSpec::Diagonal(vec![1.0, -1.0])),
        "ocp.q"
    );
    assert_eq!(
        err_key(|c| c.ocp.p = MatrixSpec::Full(vec![vec![1.0, 2.0], vec![0.0, 1.0]])),
        "ocp.p"
    );
    assert_eq!(
        err_key(|c| c.ocp.r = MatrixSpec::Diagonal(vec![0.0])),
        "ocp.r"
    );
    assert_eq!(err_key(|c| c.ocp.x_lo[1] = 2.0), "ocp.x_lo[1]");
    assert_eq!(err_key(|c| c.ocp.u_hi[0] = f64::NAN), "ocp.u_hi[0]");
    assert_eq!(err_key(|c| c.ocp.ts = f64::NAN), "ocp.ts");
    assert_eq!(err_key(|c| c.domain.hi[0] = f64::INFINITY), "domain.hi[0]");
    assert_eq!(err_key(|c| c.domain.lo = vec![0.0]), "domain.lo");
    assert_eq!(err_key(|c| c.sampling.counts = vec![3]), "sampling.counts");
    assert_eq!(err_key(|c| c.refine.target_eps = 0.0), "refine.target_eps");
    assert_eq!(err_key(|c| c.refine.budget = 80), "refine.initial");
    assert_eq!(
        err_key(|c| c.refine.initial = vec![1, 3]),
        "refine.initial[0]"
    );
    assert_eq!(
        err_key(|c| c.refine.initial = vec![3, 9000]),
        "refine.initial[1]"
    );
    assert_eq!(err_key(|c| c.refine.safety = 0.5), "refine.safety");
    assert_eq!(err_key(|c| c.refine.floor = -0.1), "refine.floor");
    assert_eq!(err_key(|c| c.refine.floor = f64::NAN), "refine.floor");
    assert_eq!(
        err_key(|c| c.refine.check.tolerance = 1.0),
        "refine.check.tolerance"
    );
    assert_eq!(
        err_key(|c| c.refine.check.jump_tol = 0.0),
        "refine.check.jump_tol"
    );
    assert_eq!(err_key(|c| c.refine.check.near = -1.0), "refine.check.near");
    assert_eq!(
        err_key(|c| c.sampling.sampler = SamplerKind::Adaptive),
        "sampling.sampler"
    );
    assert_eq!(err_key(|c| c.solver.tol = 0.0), "solver.tol");
    assert_eq!(
        err_key(|c| c.solver.retry_budget = 1001),
        "solver.retry_budget"
    );
    assert_eq!(
        err_key(
            |c| c.system = System::Pendulum(crate::problem::model::Pendulum {
                m: -1.0,
                ..Default::default()
            })
        ),
        "system.m"
    );
}

#[test]
fn parse_errors_name_the_key() {
    let bad = PENDULUM_TOML.replace("horizon = 20", "horizon = \"twenty\"");
    let e = ProblemConfig::from_toml_str(&bad, "f.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("horizon") && e.contains("f.toml"), "{e}");
    let unknown = format!("{PENDULUM_TOML}\n[extra]\nfoo = 1\n");
    let e = ProblemConfig::from_toml_str(&unknown, "f.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("extra"), "{e}");
}

#[test]
fn problem_hash_tracks_labels_only() {
    let a = ProblemConfig::default();
    let mut b = a.clone();
    b.sampling.seed = 7;
    assert_eq!(a.problem_hash(), b.problem_hash());
    b.ocp.horizon = 21;
    assert_ne!(a.problem_hash(), b.problem_hash());
}

/// The problem hashes of the shipped problem files, pinned (values from `trainer sample`
/// before `ocp.x_ref`/`ocp.u_ref` existed): optional `[ocp]` keys are not serialised when
/// absent, so existing files keep their labels' hash and their datasets stay valid.
#[test]
fn shipped_problem_hashes_are_pinned() {
    for (f, want) in [
        (
            "pendulum.toml",
            "9d383effa46fea17409cb19a0bb627808f36a952b9df9e09ca5810db9a939c50",
        ),
        (
            "cartpole.toml",
            "b858d5e0eb5f54c47dbec2c0f62ca087439f7568c86ceee81ee841af32e90138",
        ),
        (
            "double_integrator.toml",
            "f4db40c32f7575befab258e182acb080057dabe1bec1260518273e74dae3a14d",
        ),
        (
            "pendulum_robust.toml",
            "9d383effa46fea17409cb19a0bb627808f36a952b9df9e09ca5810db9a939c50",
        ),
        (
            "pendulum_robust_small.toml",
            "c32c72ee1695d1e88e6cac438d9f8495198a19395b2d1f1dd540065baaf77553",
        ),
        (
            "pendulum_ode.toml",
            "e990a7da2a82cb54b36524f84130ce59f360758ee680b0aba6c4dff16cdf12b1",
        ),
        (
            "double_integrator_ode.toml",
            "47c075af6eb592729077d495fa4bb32142a9a09f361991acedc6963fa8651f5f",
        ),
    ] {
        let path = std::path::PathBuf::from(DIR).join(f);
        let cfg = ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(cfg.problem_hash(), want, "{f}");
    }
}

/// A setpoint enters the hash (it changes the labels); the origin stated explicitly is
/// another problem file but the same OCP, and hashes differently only through the key.
#[test]
fn setpoint_keys_enter_the_hash_only_when_given() {
    let a = ProblemConfig::default();
    let mut b = a.clone();
    b.ocp.x_ref = Some(vec![0.5, 0.0]);
    // The pendulum rests at 0.5 rad under the torque computed from the model.
    b.settle_setpoint().unwrap();
    assert_ne!(a.problem_hash(), b.problem_hash());
    let mut c = a.clone();
    c.ocp.u_ref = Some(vec![0.0]);
    assert_ne!(a.problem_hash(), c.problem_hash());
    // Round trip through TOML (the dataset header's copy).
    let back = ProblemConfig::from_toml_str(&toml::to_string(&b).unwrap(), "b").unwrap();
    assert_eq!(back, b);
    assert!(!toml::to_string(&a).unwrap().contains("x_ref"));
}

/// `ocp.x_ref` / `ocp.u_ref`: lengths, finiteness, inside X, the state and the input
/// bounds; the messages name the key, the index and, for an expression plant, the state.
#[test]
fn setpoint_validation_names_key_and_state() {
    assert_eq!(err_key(|c| c.ocp.x_ref = Some(vec![0.0])), "ocp.x_ref");
    assert_eq!(err_key(|c| c.ocp.u_ref = Some(vec![0.0, 1.0])), "ocp.u_ref");
    assert_eq!(
        err_key(|c| c.ocp.x_ref = Some(vec![0.0, f64::NAN])),
        "ocp.x_ref[1]"
    );
    assert_eq!(
        err_key(|c| c.ocp.x_ref = Some(vec![0.0, f64::INFINITY])),
        "ocp.x_ref[1]"
    );
    // Outside X = [−2π, 2π] × [−1, 1] of the default.
    assert_eq!(
        err_key(|c| c.ocp.x_ref = Some(vec![7.0, 0.0])),
        "ocp.x_ref[0]"
    );
    // Inside X, outside the state bounds.
    assert_eq!(
        err_key(|c| {
            c.domain.hi[1] = 2.0;
            c.ocp.x_ref = Some(vec![0.0, 1.5]);
        }),
        "ocp.x_ref[1]"
    );
    assert_eq!(err_key(|c| c.ocp.u_ref = Some(vec![15.5])), "ocp.u_ref[0]");
    let mut ok = ProblemConfig::default();
    ok.ocp.x_ref = Some(vec![1.0, -0.5]);
    ok.ocp.u_ref = Some(vec![-15.0]);
    ok.validate().unwrap();
    // Expression plant: the names are in the message.
    let text =
        std::fs::read_to_string(std::path::PathBuf::from(DIR).join("double_integrator_ode.toml"))
            .unwrap()
            .replace("[domain]", "x_ref = [0.5, 0.0, 1.0]\n[domain]");
    let e = ProblemConfig::from_toml_str(&text, "f")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("ocp.x_ref") && e.contains("position, velocity"),
        "{e}"
    );
    let text = text.replace("x_ref = [0.5, 0.0, 1.0]", "x_ref = [4.5, 0.0]");
    let e = ProblemConfig::from_toml_str(&text, "f")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("ocp.x_ref[0]") && e.contains("(position)") && e.contains("domain.hi[0]"),
        "{e}"
    );
    let text = text.replace("x_ref = [4.5, 0.0]", "x_ref = [0.5, 0.0]\nu_ref = [2.0]");
    let e = ProblemConfig::from_toml_str(&text, "f")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("ocp.u_ref[0]") && e.contains("(force)") && e.contains("ocp.u_hi[0]"),
        "{e}"
    );
}

/// `training.hold_setpoint`: on by default and not written when off (stored copies and
/// the training hash are those of a file that never mentions it); a stored copy without it
/// reads as off.
#[test]
fn hold_setpoint_is_stored_only_when_on() {
    let on = ProblemConfig::default();
    assert!(on.training.hold_setpoint && on.refine.training.hold_setpoint);
    let text = toml::to_string(&on).unwrap();
    assert!(text.contains("hold_setpoint = true"), "{text}");
    assert_eq!(ProblemConfig::from_stored_toml(&text, "s").unwrap(), on);
    let off_text = format!("{PENDULUM_TOML}\n[training]\nhold_setpoint = false\n");
    let off = ProblemConfig::from_toml_str(&off_text, "f").unwrap();
    assert!(!off.training.hold_setpoint);
    let stored = toml::to_string(&off).unwrap();
    assert!(!stored.contains("hold_setpoint"), "{stored}");
    assert_eq!(ProblemConfig::from_stored_toml(&stored, "s").unwrap(), off);
    // A user's file without the key: on.
    assert!(
        ProblemConfig::from_toml_str(&stored, "f")
            .unwrap()
            .training
            .hold_setpoint
    );
}

/// `training.precision`: f32 by default and written only when f32; a stored copy without it
/// (every copy stored before the f32 engine existed) reads as f64; a bad value names the key.
#[test]
fn precision_is_stored_only_when_f32() {
    use crate::problem::Precision;
    let f32s = ProblemConfig::default();
    assert_eq!(f32s.training.precision, Precision::F32);
    assert_eq!(f32s.refine.training.precision, Precision::F32);
    let text = toml::to_string(&f32s).unwrap();
    assert!(text.contains("precision = \"f32\""), "{text}");
    assert_eq!(ProblemConfig::from_stored_toml(&text, "s").unwrap(), f32s);
    let f64_text = format!("{PENDULUM_TOML}\n[training]\nprecision = \"f64\"\n");
    let f64s = ProblemConfig::from_toml_str(&f64_text, "f").unwrap();
    assert_eq!(f64s.training.precision, Precision::F64);
    let stored = toml::to_string(&f64s).unwrap();
    assert!(!stored.contains("precision = "), "{stored}");
    assert_eq!(ProblemConfig::from_stored_toml(&stored, "s").unwrap(), f64s);
    // A user's file without the key: f32.
    assert_eq!(
        ProblemConfig::from_toml_str(&stored, "f")
            .unwrap()
            .training
            .precision,
        Precision::F32
    );
    let bad = format!("{PENDULUM_TOML}\n[training]\nprecision = \"f16\"\n");
    let e = ProblemConfig::from_toml_str(&bad, "bad.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("bad.toml") && e.contains("precision"), "{e}");
}

/// `[refine.training]` changes only the keys it names; the rest keep the refine defaults
/// (2-32-32-1, saturation-aware, …), not the `[training]` ones. Unknown keys and wrong
/// types are still errors that name the key and the file; stored copies round-trip.
#[test]
fn refine_training_keys_replace_only_themselves() {
    let defaults = crate::problem::RefineSettings::default().training;
    let seeded = format!("{PENDULUM_TOML}\n[refine.training]\nseed = 7\n");
    let cfg = ProblemConfig::from_toml_str(&seeded, "f.toml").unwrap();
    let t = &cfg.refine.training;
    assert_eq!(t.seed, 7);
    assert_eq!(
        crate::problem::TrainSettings {
            seed: defaults.seed,
            ..t.clone()
        },
        defaults
    );
    assert_eq!(t.hidden, vec![32, 32]);
    assert!(t.saturation_aware);
    // The `[training]` table is untouched by it.
    assert_eq!(cfg.training, ProblemConfig::default().training);
    assert_eq!(
        ProblemConfig::from_stored_toml(&toml::to_string(&cfg).unwrap(), "s").unwrap(),
        cfg
    );
    for (bad, key) in [("sed = 7", "sed"), ("epochs = \"many\"", "epochs")] {
        let text = format!("{PENDULUM_TOML}\n[refine.training]\n{bad}\n");
        let e = ProblemConfig::from_toml_str(&text, "f.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains(key) && e.contains("f.toml"), "{e}");
    }
}

/// `[system] time_unit`: the unit of ẋ and of `ocp.ts` for reports (default `s`, written
/// back only when given; a bad one names the key).
#[test]
fn time_unit_is_read_checked_and_round_trips() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/pendulum_ode.toml"
    ))
    .unwrap();
    let plain = ProblemConfig::from_toml_str(&text, "p").unwrap();
    assert_eq!(plain.system.time_unit(), "s");
    assert!(!plain.to_toml_string().unwrap().contains("time_unit"));
    let with = text.replacen("[system]\n", "[system]\ntime_unit = \"min\"\n", 1);
    assert_ne!(with, text);
    let cfg = ProblemConfig::from_toml_str(&with, "p").unwrap();
    assert_eq!(cfg.system.time_unit(), "min");
    let back = ProblemConfig::from_toml_str(&cfg.to_toml_string().unwrap(), "b").unwrap();
    assert_eq!(back.system.time_unit(), "min");
    assert_eq!(ProblemConfig::default().system.time_unit(), "s");
    let bad = text.replacen("[system]\n", "[system]\ntime_unit = \"\"\n", 1);
    let e = ProblemConfig::from_toml_str(&bad, "p")
        .unwrap_err()
        .to_string();
    assert!(e.contains("system.time_unit"), "{e}");
}

/// `closed_loop.mismatch`: scenarios named by the parameter, checked against the plant;
/// without it the mass scenario only for a plant with a mass.
#[test]
fn mismatch_scenarios_are_named_by_their_parameter() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/arm.toml"))
        .unwrap();
    // The arm has parameters g, l, c and no mass: no default scenario.
    let arm = ProblemConfig::from_toml_str(&text, "arm").unwrap();
    assert!(arm.closed_loop.mismatch_scenarios(false).is_empty());
    let with = text.replacen(
        "[closed_loop]\n",
        "[closed_loop]\nmismatch = [{ parameter = \"l\", relative = 0.2 }]\n",
        1,
    );
    let cfg = ProblemConfig::from_toml_str(&with, "arm").unwrap();
    let sc = cfg.closed_loop.mismatch_scenarios(false);
    assert_eq!((sc.len(), sc[0].tag.as_str()), (1, "l"));
    assert_eq!(sc[0].parameter.as_deref(), Some("l"));
    let long = cfg.system.with_parameter_scaled("l", 1.2).unwrap();
    let params = long.parameter_names();
    assert!(params.contains(&"l".to_string()), "{params:?}");
    assert_ne!(long, cfg.system);
    assert!(cfg.system.with_parameter_scaled("m", 1.2).is_none());
    let bad = text.replacen(
        "[closed_loop]\n",
        "[closed_loop]\nmismatch = [{ parameter = \"mass\", relative = 0.1 }]\n",
        1,
    );
    let e = ProblemConfig::from_toml_str(&bad, "arm")
        .unwrap_err()
        .to_string();
    assert!(e.contains("closed_loop.mismatch[0].parameter"), "{e}");
    assert!(e.contains("c, g, l"), "{e}");
    // The pendulum keeps the paper's mass scenario by default; its fields can be named.
    let p = ProblemConfig::default();
    let sc = p.closed_loop.mismatch_scenarios(true);
    assert_eq!(
        (sc[0].tag.as_str(), sc[0].parameter.clone()),
        ("mass", None)
    );
    match p.system.with_parameter_scaled("g", 0.5).unwrap() {
        crate::problem::model::System::Pendulum(q) => assert_eq!(q.g, 9.81 * 0.5),
        other => panic!("{other:?}"),
    }
}

/// `ocp.x_scale` / `ocp.u_scale`: one finite entry > 0 per state (input), errors naming the
/// key and the index; the defaults are the half-widths of X and U; neither enters the
/// problem hash.
#[test]
fn norm_scales_are_validated_defaulted_and_not_hashed() {
    assert_eq!(
        err_key(|c| c.ocp.x_scale = Some(vec![1.0, 0.0])),
        "ocp.x_scale[1]"
    );
    assert_eq!(
        err_key(|c| c.ocp.u_scale = Some(vec![f64::INFINITY])),
        "ocp.u_scale[0]"
    );
    assert_eq!(
        err_key(|c| c.ocp.u_scale = Some(vec![-2.0])),
        "ocp.u_scale[0]"
    );
    assert_eq!(err_key(|c| c.ocp.x_scale = Some(vec![1.0])), "ocp.x_scale");
    let text = PENDULUM_TOML.replacen("u_scale = [1.0]", "u_scale = [0.0]", 1);
    let e = ProblemConfig::from_toml_str(&text, "configs/mine.toml").unwrap_err();
    assert!(e.to_string().contains("`ocp.u_scale[0]`"), "{e}");
    let mut c = ProblemConfig::default();
    assert_eq!(c.ocp.x_scale, Some(vec![1.0, 1.0]));
    let h = c.problem_hash();
    c.ocp.x_scale = None;
    c.ocp.u_scale = None;
    assert_eq!(c.problem_hash(), h);
    let tau = std::f64::consts::TAU;
    assert_eq!(
        c.ocp.x_scale_or_default(&c.domain.lo, &c.domain.hi),
        vec![tau, 1.0]
    );
    assert_eq!(c.ocp.u_scale_or_default(), vec![15.0]);
}

/// `[training] outputs` and `sequence_weights`: parsed, the default stores as before, and
/// the weights are checked (only with a sequence net, one per step, finite ≥ 0, w₀ > 0).
#[test]
fn sequence_outputs_and_weights_are_validated() {
    let text = format!("{PENDULUM_TOML}\n[training]\noutputs = \"sequence\"\n");
    let c = ProblemConfig::from_toml_str(&text, "x").unwrap();
    assert!(c.keeps_sequences());
    assert!(!ProblemConfig::default().keeps_sequences());
    assert!(!toml::to_string(&ProblemConfig::default())
        .unwrap()
        .contains("outputs"));
    let seq = |c: &mut ProblemConfig, w: Vec<f64>| {
        c.training.outputs = Outputs::Sequence;
        c.training.sequence_weights = Some(w);
    };
    assert_eq!(
        err_key(|c| c.training.sequence_weights = Some(vec![1.0; 20])),
        "training.sequence_weights"
    );
    assert_eq!(
        err_key(|c| seq(c, vec![1.0; 19])),
        "training.sequence_weights"
    );
    let mut w = vec![1.0; 20];
    w[3] = f64::NAN;
    assert_eq!(
        err_key(|c| seq(c, w.clone())),
        "training.sequence_weights[3]"
    );
    let mut w = vec![1.0; 20];
    w[0] = 0.0;
    assert_eq!(
        err_key(|c| seq(c, w.clone())),
        "training.sequence_weights[0]"
    );
    let mut ok = ProblemConfig::default();
    seq(&mut ok, vec![0.5; 20]);
    ok.validate().unwrap();
    assert_eq!(ok.training.step_weights(20), vec![0.5; 20]);
}

/// `closed_loop.safety`: needs a sequence net (the error names the key and the fix), the run
/// counts are bounded, and the defaults are not serialised (hashes of runs without the study
/// unchanged).
#[test]
fn the_safety_study_needs_a_sequence_net() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/cartpole_safe.toml"
    ))
    .unwrap();
    let cfg = ProblemConfig::from_toml_str(&text, "cartpole_safe").unwrap();
    assert!(cfg.closed_loop.safety);
    assert_eq!(cfg.closed_loop.safety_runs, 10_000);
    let first = text.replacen("outputs = \"sequence\"", "outputs = \"first\"", 1);
    let e = ProblemConfig::from_toml_str(&first, "c")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("closed_loop.safety") && e.contains("outputs = \"sequence\""),
        "{e}"
    );
    let zero = text.replacen("\nsafety = true", "\nsafety = true\nsafety_runs = 0", 1);
    let e = ProblemConfig::from_toml_str(&zero, "c")
        .unwrap_err()
        .to_string();
    assert!(e.contains("closed_loop.safety_runs"), "{e}");
    let plain = toml::to_string(&ProblemConfig::default().closed_loop).unwrap();
    assert!(!plain.contains("safety"), "{plain}");
}

/// `[refine] target_eps` not given: 2.5 % of the input range in the certificate's norm —
/// the pendulum's 0.75 N·m unscaled (|u| ≤ 15, u_scale = 1), 0.05 in the default scaled
/// norm of the CSTR (1 K of its 40 K coolant range); given, the file's value; a problem
/// stored and read back keeps its target.
#[test]
fn the_default_target_eps_is_a_fraction_of_the_scaled_input_range() {
    let load = |f: &str| {
        ProblemConfig::load(&std::path::PathBuf::from(DIR).join(f))
            .unwrap_or_else(|e| panic!("{f}: {e}"))
    };
    let p = load("pendulum.toml");
    assert_eq!(p.refine.target_eps, 0.75);
    assert!(
        p.refine.is_default(),
        "the pendulum's [refine] is the default"
    );
    let c = load("cstr.toml");
    assert_eq!(c.ocp.u_scale_or_default(), vec![20.0]);
    assert!(
        (c.refine.target_eps - 0.05).abs() < 1e-15,
        "{}",
        c.refine.target_eps
    );
    // Per input: ε·s_u = 1 K = 2.5 % of 280..320 K.
    assert!((c.refine.target_eps * 20.0 - 1.0).abs() < 1e-12);
    let a = load("arm.toml");
    assert_eq!(a.refine.target_eps, 0.03, "the file's value");
    // Stored and read back: the same target (written out since it is not 0.75).
    let back = ProblemConfig::from_stored_toml(&c.to_toml_string().unwrap(), "stored").unwrap();
    assert_eq!(back.refine.target_eps, c.refine.target_eps);
    // Two inputs, default scales: 0.025 × 2√2.
    let mut o = c.ocp.clone();
    o.u_lo = vec![-1.0, 0.0];
    o.u_hi = vec![1.0, 100.0];
    let t = refine::default_target_eps(&o);
    assert!((t - 0.025 * 8f64.sqrt()).abs() < 1e-15, "{t}");
}

/// `[training] sequence_form`: feedback by default for a sequence net in a file, open (and
/// not written) otherwise; a stored copy without it is open (models made before it); an
/// explicit form round-trips through a stored copy; a feedback form set in code without a
/// sequence net is refused naming the key.
#[test]
fn sequence_form_defaults_and_stored_copies() {
    use crate::problem::SequenceForm;
    let text = format!("{PENDULUM_TOML}\n[training]\noutputs = \"sequence\"\n");
    let c = ProblemConfig::from_toml_str(&text, "x").unwrap();
    assert_eq!(c.training.sequence_form, SequenceForm::Feedback);
    let stored = c.to_toml_string().unwrap();
    assert!(stored.contains("sequence_form = \"feedback\""));
    assert_eq!(ProblemConfig::from_stored_toml(&stored, "s").unwrap(), c);
    let old = stored.replace("sequence_form = \"feedback\"\n", "");
    assert_eq!(
        ProblemConfig::from_stored_toml(&old, "s")
            .unwrap()
            .training
            .sequence_form,
        SequenceForm::Open
    );
    let open = format!("{text}sequence_form = \"open\"\n");
    let c = ProblemConfig::from_toml_str(&open, "x").unwrap();
    assert_eq!(c.training.sequence_form, SequenceForm::Open);
    assert!(!c.to_toml_string().unwrap().contains("sequence_form"));
    let first = ProblemConfig::from_toml_str(PENDULUM_TOML, "x").unwrap();
    assert_eq!(first.training.sequence_form, SequenceForm::Open);
    assert!(!first.to_toml_string().unwrap().contains("sequence_form"));
    assert_eq!(
        err_key(|c| c.training.sequence_form = SequenceForm::Feedback),
        "training.sequence_form"
    );
}

/// `closed_loop.safety_decrease`: default 0.5 (not serialised), 0 = the strict rule (no σ on
/// the device), outside [0, 1] refused naming the key.
#[test]
fn safety_decrease_default_range_and_device_value() {
    let c = ProblemConfig::default();
    assert_eq!(c.closed_loop.safety_decrease, 0.5);
    assert_eq!(c.closed_loop.decrease(), Some(0.5));
    assert!(!toml::to_string(&c).unwrap().contains("safety_decrease"));
    let mut strict = c.clone();
    strict.closed_loop.safety_decrease = 0.0;
    assert_eq!(strict.closed_loop.decrease(), None);
    strict.validate().unwrap();
    for bad in [-0.1, 1.5, f64::NAN] {
        assert_eq!(
            err_key(|c| c.closed_loop.safety_decrease = bad),
            "closed_loop.safety_decrease"
        );
    }
}
