//! Tests of the statistical tier: the Clopper–Pearson bound against independent
//! computations, its coverage, the seeds, the order statistic, and the conditional bounds.
use super::*;

/// Against scipy 1.x `beta.ppf(1 − β, k + 1, n − k)` (an independent implementation
/// of the same quantile), computed once with Python and written here.
#[test]
fn matches_the_beta_quantile() {
    for (n, k, c, want) in [
        (10, 1, 0.95, 0.394_163_302_436_504_66),
        (200, 3, 0.99, 0.049_348_311_348_674_84),
        (500_000, 0, 0.99, 9.210_297_956_921_517e-6),
        (100_000, 7, 0.99, 1.599_924_346_890_874_6e-4),
        (50, 49, 0.9, 0.997_895_008_295_863_2),
        (1_000_000, 250, 0.99, 2.893_142_251_211_049_6e-4),
    ] {
        let got = clopper_pearson_upper(n, k, c);
        assert!(
            (got - want).abs() <= 1e-9 * want,
            "n {n} k {k} c {c}: {got} vs {want}"
        );
        assert!(got >= want * (1.0 - 1e-12), "never rounded down");
    }
}

#[test]
fn zero_exceedances_closed_form_and_edges() {
    for n in [1u64, 7, 1000, 500_000] {
        for c in [0.9f64, 0.99, 0.999] {
            let want = 1.0 - (1.0 - c).powf(1.0 / n as f64);
            let got = clopper_pearson_upper(n, 0, c);
            assert!((got - want).abs() <= 1e-10 * want, "{n} {c}: {got} {want}");
        }
    }
    assert_eq!(clopper_pearson_upper(10, 10, 0.99), 1.0);
    assert_eq!(clopper_pearson_upper(0, 0, 0.99), 1.0);
    assert!(clopper_pearson_upper(10, 1, 1.0).is_nan());
    // Monotone in k.
    let b: Vec<f64> = (0..20)
        .map(|k| clopper_pearson_upper(100, k, 0.99))
        .collect();
    assert!(b.windows(2).all(|w| w[0] < w[1]), "{b:?}");
}

/// Coverage: over 4000 seeded binomial draws, the bound is below the true p in at most
/// a β share of them (plus Monte Carlo slack).
#[test]
fn covers_the_true_probability() {
    for (p, n, c) in [(0.02, 200u64, 0.95), (0.001, 3000, 0.9), (0.3, 40, 0.99)] {
        let draws = 4000u64;
        let mut misses = 0;
        for d in 0..draws {
            let k = (0..n)
                .filter(|&i| crate::rng::uniform(91, d, i) < p)
                .count() as u64;
            misses += (clopper_pearson_upper(n, k, c) < p) as u64;
        }
        let rate = misses as f64 / draws as f64;
        let beta = 1.0 - c;
        // 4 standard deviations of the Monte Carlo estimate.
        let slack = 4.0 * (beta * (1.0 - beta) / draws as f64).sqrt();
        assert!(
            rate <= beta + slack,
            "p {p} n {n}: miss rate {rate} > β {beta}"
        );
    }
}

/// The seed is a function of the model's hash and the user seed, different for another
/// model or another user seed; a draw containing a training state is refused, naming it.
#[test]
fn seeds_follow_the_model_and_training_states_are_refused() {
    let a = statistical_seed("abc", DEFAULT_SEED);
    assert_eq!(a, statistical_seed("abc", DEFAULT_SEED));
    assert_ne!(a, statistical_seed("abd", DEFAULT_SEED));
    assert_ne!(a, statistical_seed("abc", DEFAULT_SEED + 1));
    let cfg = ProblemConfig::default();
    let opts = StatisticalOptions {
        samples: 5,
        ..Default::default()
    };
    let sc = sampling_problem(&cfg, &opts, a);
    assert_eq!((sc.sampling.seed, sc.sampling.n), (a, 5));
    let drawn = [vec![0.5, 0.25], vec![0.1, 0.2]];
    let it = || drawn.iter().map(|x| x.as_slice());
    assert!(check_fresh(it(), &[vec![0.3, 0.25]], a).is_ok());
    let e = check_fresh(it(), &[vec![0.3, 0.25], vec![0.1, 0.2]], a).unwrap_err();
    assert!(matches!(
        e,
        StatisticalError::TrainingState { index: 1, .. }
    ));
    assert!(e.to_string().contains("[0.1, 0.2]"), "{e}");
}

#[test]
fn eps_for_probability_picks_the_order_statistic() {
    // 1000 errors 0.001..1.0; n = 1000 at 99 %: k = 0 gives 4.6e-3.
    let errors: Vec<f64> = (1..=1000).map(|i| i as f64 / 1000.0).collect();
    assert_eq!(eps_for_probability(&errors, 1e-3, 0.99), None);
    let p = clopper_pearson_upper(1000, 0, 0.99);
    assert_eq!(eps_for_probability(&errors, p, 0.99), Some(1.0));
    let p5 = clopper_pearson_upper(1000, 5, 0.99);
    let e = eps_for_probability(&errors, p5, 0.99).unwrap();
    // Exceedances of e are exactly 5, and its bound is the target.
    assert_eq!(errors.iter().filter(|v| **v > e).count(), 5);
    let s = from_errors(&errors, e, 0.99, 0, p5);
    assert_eq!(s.exceedances, 5);
    assert!(s.p_exceed_upper <= p5);
    // An unlabelled state counts as an exceedance, at any ε.
    let mut with_nan = errors.clone();
    with_nan[0] = f64::NAN;
    let s = from_errors(&with_nan, 10.0, 0.99, 0, 0.5);
    assert_eq!((s.exceedances, s.unlabelled), (1, 1));
    assert_eq!(s.max_error, 1.0);
}

/// The bound is conditional on the labelled states: an unlabelled state (NaN) is not an
/// exceedance of ε there, and the unlabelled share has its own Clopper–Pearson bound. 250
/// states, 50 unlabelled, 3 of the 200 labelled over ε, at 99 %: the conditional bound is
/// p̄(200, 3) = 0.049348311348674845 (scipy `beta.ppf(0.99, 4, 197)`), the unlabelled share's
/// p̄(250, 50) = 0.2654580085674249 (the root of P(Bin(250, p) ≤ 50) = 0.01 with the CDF
/// summed exactly in rationals, Python `fractions`, bisected to 1e-16; the same script gives
/// 0.04934831134867484 for p̄(200, 3), agreeing with scipy). Before, the 50 unlabelled states
/// were 50 exceedances and no block said so.
#[test]
fn conditional_on_labelled_states_and_the_unlabelled_share() {
    let mut errors: Vec<f64> = (0..200).map(|i| 0.001 * i as f64 / 200.0).collect();
    errors[7] = 0.5;
    errors[70] = 0.7;
    errors[170] = f64::INFINITY; // a non-finite output at a labelled state: an exceedance
    errors.extend(std::iter::repeat_n(f64::NAN, 50));
    let s = from_errors(&errors, 0.1, 0.99, 0, 1e-3);
    // The unconditional block as before: unlabelled states count as exceedances.
    assert_eq!((s.samples, s.exceedances, s.unlabelled), (250, 53, 50));
    let g = s.given_labelled.clone().expect("the conditional block");
    assert_eq!((g.samples, g.exceedances), (200, 3));
    let want = 0.049_348_311_348_674_845;
    assert!((g.p_exceed_upper - want).abs() <= 1e-9 * want, "{g:?}");
    let u = s.unlabelled_share.clone().expect("the unlabelled share");
    assert_eq!((u.unlabelled, u.samples), (50, 250));
    let want = 0.265_458_008_567_424_9;
    assert!((u.p_upper - want).abs() <= 1e-9 * want, "{u:?}");
    // The conditional ε at a target the 200 labelled states can reach: the 4th largest
    // labelled error exceeded by 3 (the bound p̄(200, 3) is the target itself).
    let s = from_errors(&errors, 0.1, 0.99, 0, want.max(0.05));
    let e = s.given_labelled.unwrap().eps_at_p_target.unwrap();
    assert!(e.is_finite() && e < 0.5, "{e}");
    assert_eq!(s.eps_at_p_target, Some(f64::INFINITY), "unconditionally, ∞");
    // Written to JSON: both blocks, no null.
    let json = serde_json::to_string(&from_errors(&errors, 0.1, 0.99, 0, 0.05)).unwrap();
    assert!(json.contains("\"given_labelled\"") && json.contains("\"unlabelled_share\""));
}

/// Soft labels are labelled but not MPC-feasible: the block given feasible states leaves
/// them out (with the unlabelled ones) and counts both in the infeasible share, whose bound
/// is the same p̄(250, 50) as above when 20 unlabelled and 30 soft-labelled states make the
/// 50; the soft states' largest error is reported, and it sets neither the conditional
/// level nor its exceedances. The feasible block's level is the largest feasible error
/// here (k* = 0 with 200 states at p = 0.025: p̄(200, 0) = 0.0228, p̄(200, 1) = 0.0327).
#[test]
fn given_feasible_states_soft_labels_are_infeasible() {
    let mut errors: Vec<f64> = (0..200).map(|i| 0.001 * i as f64 / 200.0).collect();
    errors[9] = 0.08; // the largest feasible error
    errors.extend(std::iter::repeat_n(f64::NAN, 20)); // unlabelled
    let soft: Vec<f64> = (0..30).map(|i| if i == 4 { 0.9 } else { 0.01 }).collect();
    errors.extend(&soft); // soft-labelled, one far off
    let feasible: Vec<bool> = (0..errors.len()).map(|i| i < 200).collect();
    let s = from_errors(&errors, 0.1, 0.99, 0, 0.025).with_feasibility(&errors, &feasible);
    assert!(clopper_pearson_upper(200, 1, 0.99) > 0.025);
    // The labelled block still counts the soft state's 0.9 as an exceedance.
    assert_eq!(s.given_labelled.as_ref().unwrap().exceedances, 1);
    let g = s.given_feasible.clone().expect("the feasible block");
    assert_eq!((g.samples, g.exceedances), (200, 0));
    assert_eq!(g.p_exceed_upper, clopper_pearson_upper(200, 0, 0.99));
    assert_eq!(g.eps_at_p_target, Some(0.08));
    let u = s.infeasible_share.clone().expect("the infeasible share");
    assert_eq!((u.unlabelled, u.samples), (50, 250));
    let want = 0.265_458_008_567_424_9;
    assert!((u.p_upper - want).abs() <= 1e-9 * want, "{u:?}");
    let soft = s.soft_labelled.clone().expect("the soft states");
    assert_eq!((soft.states, soft.max_error), (30, 0.9));
    // A non-finite output at a feasible state is an exceedance there.
    let mut bad = errors.clone();
    bad[3] = f64::INFINITY;
    let s = from_errors(&bad, 0.1, 0.99, 0, 0.025).with_feasibility(&bad, &feasible);
    assert_eq!(s.given_feasible.as_ref().unwrap().exceedances, 1);
    // Round trip through JSON, the soft block's +∞ included.
    let mut t = s.clone();
    t.soft_labelled.as_mut().unwrap().max_error = f64::INFINITY;
    let json = serde_json::to_string(&t).unwrap();
    assert!(json.contains("\"given_feasible\"") && json.contains("\"infeasible_share\""));
    let back: Statistical = serde_json::from_str(&json).unwrap();
    assert_eq!(back.soft_labelled.unwrap().max_error, f64::INFINITY);
    assert_eq!(back.given_feasible, t.given_feasible);
}

/// The bounding box of the unlabelled states: the smallest box holding them.
#[test]
fn bounding_box_of_states() {
    let xs = [vec![0.5, 350.0], vec![0.7, 340.0], vec![0.6, 360.0]];
    let b = bounding_box(xs.iter().map(|x| x.as_slice())).unwrap();
    assert_eq!(b, (vec![0.5, 340.0], vec![0.7, 360.0]));
    assert_eq!(bounding_box(std::iter::empty::<&[f64]>()), None);
}

/// The draw aims at `target` labelled states: unchanged without unlabelled states, larger
/// than target / (1 − u/n) (the upper bound on the share is above the observed one), capped
/// at 4·target; and with the CSTR's validation share (149 of 1000) enough that the expected
/// labelled count reaches the target.
#[test]
fn the_draw_aims_at_the_target_of_labelled_states() {
    assert_eq!(draw_for_labelled(4603, 1000, 0, 0.99), 4603);
    assert_eq!(draw_for_labelled(4603, 0, 0, 0.99), 4603);
    assert_eq!(draw_for_labelled(0, 1000, 10, 0.99), 0);
    let d = draw_for_labelled(4603, 1000, 149, 0.99);
    let observed = (4603.0 / (1.0 - 0.149_f64)).ceil() as usize;
    assert!(d > observed, "{d} vs {observed}");
    let ub = clopper_pearson_upper(1000, 149, 0.99);
    assert!((d as f64) * (1.0 - ub) >= 4603.0 - 1e-9, "{d}");
    assert!(
        (d as f64 - 1.0) * (1.0 - ub) < 4603.0,
        "{d}: not the smallest"
    );
    assert_eq!(draw_for_labelled(4603, 1000, 900, 0.99), 4 * 4603);
    assert_eq!(draw_for_labelled(100, 10, 10, 0.99), 400);
}
