//! The refinement's lattice lookup and state handling.

use super::check::leaf_of;
use super::*;

/// The refinement state of a 2-D initial grid of `counts` points per axis over the
/// problem's X (roots in row-major order, no label yet), its context and lattice.
pub(super) fn grid(cfg: &ProblemConfig, counts: [usize; 2]) -> (Ctx<'_>, RefineState, Lattice) {
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &counts);
    let mut ctx = Ctx {
        cfg,
        lat: lat.clone(),
        index: HashMap::new(),
    };
    let mut st = RefineState {
        hash: String::new(),
        points: vec![],
        nodes: vec![],
        roots: vec![],
        model: None,
        best: None,
        log: vec![],
        bounds: vec![],
        finished: false,
        jumps: vec![],
    };
    let mut new = Vec::new();
    for i in 0..counts[0] as u64 - 1 {
        for j in 0..counts[1] as u64 - 1 {
            let lo = vec![i << LEVELS, j << LEVELS];
            let n = ctx.node(&mut st, lo, vec![1 << LEVELS; 2], &mut new);
            st.roots.push(n);
        }
    }
    (ctx, st, lat)
}

#[test]
fn leaf_lookup_finds_the_cell_containing_the_state() {
    let cfg = ProblemConfig::default();
    let counts = [4usize, 3];
    let (mut ctx, mut st, lat) = grid(&cfg, counts);
    let mut new = Vec::new();
    // Random splits.
    for s in 0..300u64 {
        let leaves: Vec<usize> = (0..st.nodes.len())
            .filter(|&i| st.nodes[i].split.is_none())
            .collect();
        let n = leaves[(crate::rng::uniform(5, s, 0) * leaves.len() as f64) as usize];
        let axis = (crate::rng::uniform(5, s, 1) * 2.0) as usize;
        ctx.split(&mut st, n, axis, &mut new);
    }
    for s in 0..5000u64 {
        let x: Vec<f64> = (0..2)
            .map(|k| {
                cfg.domain.lo[k]
                    + (cfg.domain.hi[k] - cfg.domain.lo[k]) * crate::rng::uniform(6, s, k as u64)
            })
            .collect();
        let leaf = leaf_of(&st, &lat, &counts, &x);
        let node = &st.nodes[leaf];
        assert!(node.split.is_none());
        let hi: Vec<u64> = node.lo.iter().zip(&node.size).map(|(a, b)| a + b).collect();
        let (l, h) = (lat.x(&node.lo), lat.x(&hi));
        for k in 0..2 {
            assert!(
                l[k] - 1e-12 <= x[k] && x[k] <= h[k] + 1e-12,
                "{x:?} not in {l:?}..{h:?}"
            );
        }
        // Corners are the lattice points of the box.
        assert_eq!(st.points[node.corners[3]].x, h);
    }
    // The domain's upper corner belongs to a cell too.
    let leaf = leaf_of(&st, &lat, &counts, &cfg.domain.hi);
    assert!(st.nodes[leaf].split.is_none());

    // A checkpoint whose contents do not fit the lattice is refused, naming the file.
    let path = std::path::Path::new("runs/x/refine_state.bin");
    let nu = cfg.system.nu();
    assert!(st.check_consistent(&lat.max, 6, nu, path).is_ok());
    let last = st.nodes.len() - 1;
    type Edit = Box<dyn Fn(&mut RefineState)>;
    let edits: [(&str, Edit); 6] = [
        ("roots", Box::new(|s| s.roots[0] = 1 << 40)),
        ("roots", Box::new(|s| s.roots.pop().map(drop).unwrap_or(()))),
        (
            "split",
            Box::new(move |s| s.nodes[last].split = Some((0, 1, 0))),
        ),
        (
            "split",
            Box::new(move |s| s.nodes[0].split = Some((last, last, 2))),
        ),
        (
            "dims",
            Box::new(|s| s.points[3].du.pop().map(drop).unwrap_or(())),
        ),
        ("lattice", Box::new(|s| s.points[2].key[1] = u64::MAX)),
    ];
    for (what, edit) in edits {
        let mut bad = st.clone();
        edit(&mut bad);
        let e = bad.check_consistent(&lat.max, 6, nu, path).unwrap_err();
        let m = e.to_string();
        assert!(
            m.contains("runs/x/refine_state.bin") && m.contains("inconsistent"),
            "{what}: {m}"
        );
    }
}

/// `--data`: corners of the initial grid take the labels of records at their states (within
/// rounding), and only those; records off the grid, unlabelled or without a finite
/// Jacobian label nothing.
#[test]
fn first_round_corners_take_the_labels_of_records_at_their_states() {
    use crate::data::dataset::{Dataset, Record};
    let cfg = ProblemConfig::default();
    let counts = [4usize, 3];
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &counts);
    let mut ctx = Ctx {
        cfg: &cfg,
        lat,
        index: HashMap::new(),
    };
    let mut st = RefineState {
        hash: String::new(),
        points: vec![],
        nodes: vec![],
        roots: vec![],
        model: None,
        best: None,
        log: vec![],
        bounds: vec![],
        finished: false,
        jumps: vec![],
    };
    let mut pending = Vec::new();
    for r in 0..6u64 {
        let lo = vec![(r / 2) << LEVELS, (r % 2) << LEVELS];
        let n = ctx.node(&mut st, lo, vec![1 << LEVELS; 2], &mut pending);
        st.roots.push(n);
    }
    assert_eq!(pending.len(), 12);
    let rec = |i: u64, x: Vec<f64>, status: SqpStatus, du: f64| Record {
        index: i,
        x,
        u: vec![i as f64],
        du_dx: vec![du, 1.0],
        cost: 1.0,
        status,
        iterations: 0,
        kkt: 0.0,
        degeneracy: None,
        max_slack: 0.0,
        seq: Vec::new(),
    };
    let p = |i: usize| st.points[pending[i]].x.clone();
    // Rounding of another tool's last digit is absorbed.
    let nudged: Vec<f64> = p(4).iter().map(|v| v * (1.0 + 1e-15)).collect();
    let off_grid = vec![0.5 * (p(0)[0] + p(1)[0]), p(0)[1]];
    let records = vec![
        rec(0, p(0), SqpStatus::Converged, 2.0),
        rec(1, p(1), SqpStatus::Infeasible, 2.0),
        rec(2, p(2), SqpStatus::Soft, f64::NAN),
        rec(3, nudged, SqpStatus::Soft, 3.0),
        rec(4, off_grid, SqpStatus::Converged, 2.0),
    ];
    let mut data = crate::certify::refine::dataset(&cfg, &st);
    data.records = records;
    let data: Dataset = data;
    let left = take_labels(&cfg, &counts, &mut st.points, &pending, &data);
    assert_eq!(left.len(), 10, "two corners labelled by the data");
    assert!(!left.contains(&pending[0]) && !left.contains(&pending[4]));
    let a = &st.points[pending[0]];
    assert_eq!((a.u.clone(), a.du.clone()), (vec![0.0], vec![2.0, 1.0]));
    assert_eq!((a.status, a.regular), (Some(SqpStatus::Converged), false));
    assert_eq!(st.points[pending[4]].u, vec![3.0]);
    assert_eq!(st.points[pending[4]].status, Some(SqpStatus::Soft));
    assert!(st.points[pending[1]].status.is_none());
    assert!(st.points[pending[2]].status.is_none());
}

/// Cells with a corner the MPC cannot label are split around it, not left whole. The retry
/// ladder labels every state a solver failure left unlabelled in the tests we ran, so the
/// unlabelled corners here are proven-infeasible states: `configs/stiff_spring_setpoint.toml`
/// (its path and terminal constraints make a corner of X infeasible) with
/// `solver.soft_fallback = false`. The uncertified (ε_C = ∞) cells of the final tree cover
/// less of X than the initial cells that touch or contain the unlabelled corners (the old
/// rule skipped such cells and left them whole).
#[test]
fn cells_with_a_failed_corner_are_split_around_it() {
    let mut cfg = stiff_spring();
    cfg.solver.soft_fallback = false;
    let rs = quick_refine([5, 5], 300, 5, 0.5);
    let r = refine(&cfg, &rs, None, &RefineOptions::default()).unwrap();
    let st = &r.state;
    let failed: Vec<usize> = (0..st.points.len())
        .filter(|&i| st.points[i].status.is_some() && !st.points[i].labelled())
        .collect();
    assert!(
        !failed.is_empty(),
        "no unlabelled corner: the test shows nothing"
    );
    let volume = |n: &Node| -> f64 {
        n.size
            .iter()
            .map(|&s| s as f64 / (1u64 << LEVELS) as f64)
            .product()
    };
    let touches = |n: &Node| n.corners.iter().any(|c| failed.contains(c));
    let initial: f64 = st
        .roots
        .iter()
        .map(|&n| &st.nodes[n])
        .filter(|n| touches(n) || failed.iter().any(|&f| inside(n, &st.points[f].key)))
        .map(volume)
        .sum();
    let leaves: Vec<&Node> = st.nodes.iter().filter(|n| n.split.is_none()).collect();
    let uncertified: f64 = leaves
        .iter()
        .copied()
        .filter(|n| touches(n))
        .map(volume)
        .sum();
    eprintln!(
        "{} failed corners, initial cells touching them {initial}, uncertified leaves {uncertified}",
        failed.len()
    );
    assert!(uncertified < initial, "{uncertified} vs {initial}");
    // Every leaf touching a failed corner is reported infinite (never certified).
    for (n, b) in &st.bounds {
        if touches(&st.nodes[*n]) {
            assert!(b.eps.is_infinite());
        }
    }
}

/// `configs/stiff_spring_setpoint.toml`: its path and terminal constraints make part of X
/// infeasible.
pub(super) fn stiff_spring() -> ProblemConfig {
    let path = std::path::PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/stiff_spring_setpoint.toml"
    ));
    ProblemConfig::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// A small, fast refinement: an `initial` grid, `budget` solves, `rounds`, a 2-8-1 net.
pub(super) fn quick_refine(
    initial: [usize; 2],
    budget: usize,
    rounds: usize,
    target: f64,
) -> crate::problem::RefineSettings {
    let mut rs = crate::problem::RefineSettings {
        initial: initial.to_vec(),
        budget,
        max_rounds: rounds,
        target_eps: target,
        round_epochs: 5,
        ..Default::default()
    };
    rs.training.hidden = vec![8];
    rs.training.epochs = 20;
    rs
}

/// Whether the lattice point `key` lies in the closed box of `n`.
fn inside(n: &Node, key: &[u64]) -> bool {
    (0..key.len()).all(|k| n.lo[k] <= key[k] && key[k] <= n.lo[k] + n.size[k])
}

/// `refine.exclude_infeasible`: on a problem where part of X is infeasible (the stiff
/// spring's path and terminal constraints, soft fallback on), the excluded leaves are exactly
/// those whose corners are all hard-infeasible, none of them is bounded, trained on or split,
/// the certificate's boxes cover exactly their union, and `check` keeps their states apart.
#[test]
fn infeasible_cells_are_excluded_and_listed_exactly() {
    let cfg = stiff_spring();
    let rs = crate::problem::RefineSettings {
        exclude_infeasible: true,
        ..quick_refine([9, 9], 400, 4, 0.05)
    };
    let r = refine(&cfg, &rs, None, &RefineOptions::default()).unwrap();
    let st = &r.state;
    let excluded = st.excluded_leaves(true);
    assert!(
        !excluded.is_empty(),
        "no infeasible cell: the test shows nothing"
    );
    let leaves: Vec<usize> = (0..st.nodes.len())
        .filter(|&n| st.nodes[n].split.is_none())
        .collect();
    assert!(excluded.len() < leaves.len(), "everything excluded");
    for &n in &leaves {
        let all_infeasible = st.nodes[n]
            .corners
            .iter()
            .all(|&c| st.points[c].hard_infeasible());
        assert_eq!(st.excluded(n), all_infeasible);
        // Bounded iff not excluded.
        assert_eq!(st.bounds.iter().any(|(l, _)| *l == n), !all_infeasible);
    }
    // Training data: no point that is only a corner of excluded leaves.
    // (min_size 0: no exclusion for unlabelled corners, only the infeasible rule.)
    let ex = super::Exclusion {
        infeasible: true,
        min_size: vec![0; st.nodes[0].lo.len()],
    };
    let keep = super::rounds::kept_points(st, &ex);
    for (i, p) in st.points.iter().enumerate() {
        let in_included = leaves
            .iter()
            .any(|&n| !st.excluded(n) && st.nodes[n].corners.contains(&i));
        if p.hard_infeasible() && !in_included {
            assert!(!keep[i], "point {i} of an excluded cell is trained on");
        }
        if !p.hard_infeasible() {
            assert!(keep[i]);
        }
    }
    // The merged boxes: disjoint, inside X, and their volume is the excluded leaves'.
    let boxes = super::outputs::excluded_lattice_boxes(st, &ex);
    let vol = |s: &[u64]| s.iter().map(|&v| v as f64).product::<f64>();
    let leaf_vol: f64 = excluded.iter().map(|&n| vol(&st.nodes[n].size)).sum();
    let box_vol: f64 = boxes.iter().map(|(_, s)| vol(s)).sum();
    assert_eq!(leaf_vol, box_vol);
    assert!(boxes.len() <= excluded.len());
    let overlap = |a: (&[u64], &[u64]), b: (&[u64], &[u64])| {
        (0..2).all(|k| a.0[k] < b.0[k] + b.1[k] && b.0[k] < a.0[k] + a.1[k])
    };
    for (i, a) in boxes.iter().enumerate() {
        for b in &boxes[i + 1..] {
            assert!(!overlap((&a.0, &a.1), (&b.0, &b.1)), "{a:?} {b:?}");
        }
        // No included leaf reaches into a box.
        for &n in leaves.iter().filter(|&&n| !st.excluded(n)) {
            let node = &st.nodes[n];
            assert!(!overlap((&a.0, &a.1), (&node.lo, &node.size)));
        }
    }
    // The certificate lists them; the check keeps their states apart.
    let cert = super::outputs::certificate(&cfg, &rs, &r);
    let e = cert.local.excluded.as_ref().expect("excluded block");
    assert_eq!((e.cells, e.boxes.len()), (excluded.len(), boxes.len()));
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &[9, 9]);
    let total = vol(&lat.max);
    assert!((e.volume_fraction - leaf_vol / total).abs() < 1e-12);
    let c = super::check::check(&cfg, &rs, &r, 300, 5);
    assert!(
        c.excluded_states > 0,
        "no check state fell in an excluded cell"
    );
    assert!(c.labelled + c.excluded_states <= c.states);
    // Without the setting nothing is excluded (and every leaf is bounded).
    let off = crate::problem::RefineSettings {
        exclude_infeasible: false,
        ..rs.clone()
    };
    assert!(super::outputs::certificate(&cfg, &off, &r)
        .local
        .excluded
        .is_none());
}

/// With every leaf excluded nothing is certified: ε = ∞ and the target is not met (not the
/// ε = 0 of an empty maximum).
#[test]
fn no_bounded_leaf_certifies_nothing() {
    use super::rounds::{certified_all, max_eps};
    assert_eq!(max_eps(&[]), f64::INFINITY);
    assert!(!certified_all(&[], 1.0));
}

/// A cell with a corner the MPC cannot label is split down to `refine.min_cell` and then
/// excluded: it leaves the certified domain (not bounded), the certificate lists its box and
/// names the unlabelled states, and the certified ε over the other cells is finite (before,
/// such cells were split down to `min_width` and ε stayed ∞). The stiff spring without its
/// soft fallback, as above; min_cell = 1/8 of X, i.e. half an initial cell per axis.
#[test]
fn unlabelled_corners_are_excluded_at_the_smallest_cell_and_eps_is_finite() {
    let mut cfg = stiff_spring();
    cfg.solver.soft_fallback = false;
    let rs = crate::problem::RefineSettings {
        min_cell: 0.125,
        ..quick_refine([5, 5], 600, 8, 0.5)
    };
    let r = refine(&cfg, &rs, None, &RefineOptions::default()).unwrap();
    let st = &r.state;
    let lat = Lattice::new(&cfg.domain.lo, &cfg.domain.hi, &[5, 5]);
    let ex = Exclusion::new(&rs, &lat.max);
    assert_eq!(ex.min_size, vec![lat.max[0] / 8, lat.max[1] / 8]);
    let unlabelled = |c: usize| st.points[c].status.is_some() && !st.points[c].labelled();
    let excluded = st.excluded_leaves_by(&ex);
    assert!(
        !excluded.is_empty(),
        "no cell excluded: the test shows nothing"
    );
    for &n in &excluded {
        let node = &st.nodes[n];
        assert!(node.corners.iter().any(|&c| unlabelled(c)));
        // At the smallest size, or (at any size) with no labelled corner at all.
        assert!(
            node.size.iter().zip(&ex.min_size).all(|(s, m)| s <= m)
                || node.corners.iter().all(|&c| unlabelled(c))
        );
        assert!(
            !st.bounds.iter().any(|(l, _)| *l == n),
            "excluded leaf {n} bounded"
        );
    }
    // Every bounded leaf has labelled corners (an unlabelled corner is excluded or split).
    for (n, b) in &st.bounds {
        assert!(
            !st.nodes[*n].corners.iter().any(|&c| unlabelled(c)),
            "{b:?}"
        );
    }
    let eps = super::rounds::max_eps(&st.bounds);
    assert!(eps.is_finite(), "certified ε {eps}");
    // The certificate: ε finite, the excluded boxes and the unlabelled states named.
    let cert = super::outputs::certificate(&cfg, &rs, &r);
    assert!(cert.base.eps.is_finite(), "certificate ε {}", cert.base.eps);
    let e = cert.local.excluded.as_ref().expect("excluded block");
    assert_eq!(e.cells, excluded.len());
    assert!(!e.boxes.is_empty() && e.note.contains("min_cell"));
    assert!(!e.unlabelled_states.is_empty());
    for x in &e.unlabelled_states {
        let i = st
            .points
            .iter()
            .position(|p| &p.x == x)
            .expect("a refinement point");
        assert!(unlabelled(i), "{x:?} is labelled");
        assert!(
            super::super::statistical::in_any_box(x, &e.boxes),
            "{x:?} outside the boxes"
        );
    }
}

/// A run with unlabelled corners (as in `cells_with_a_failed_corner_are_split_around_it`):
/// every cell with ε_C = ∞ is named with its unlabelled corner states, their solve status
/// and the cause; the run says why it stopped; the round sink sees every round, marked best
/// exactly when ε is finite and below every earlier round's.
#[test]
fn infinite_cells_are_named_and_every_round_reaches_the_sink() {
    use std::sync::{Arc, Mutex};
    let mut cfg = stiff_spring();
    cfg.solver.soft_fallback = false;
    let rs = quick_refine([5, 5], 300, 5, 0.5);
    let seen = Arc::new(Mutex::new(Vec::<(f64, bool)>::new()));
    let sink = seen.clone();
    let opts = RefineOptions {
        on_result: Some(RoundSink(Arc::new(move |r: &Refined, best: bool| {
            let e = super::rounds::max_eps(&r.state.bounds);
            assert_eq!(r.stopped, StopReason::Running);
            sink.lock().unwrap().push((e, best));
        }))),
        ..Default::default()
    };
    let r = refine(&cfg, &rs, None, &opts).unwrap();
    let seen = seen.lock().unwrap();
    assert_eq!(seen.len(), r.state.log.len(), "one call per round");
    let mut least = f64::INFINITY;
    for &(e, best) in seen.iter() {
        assert_eq!(best, e.is_finite() && e < least, "{seen:?}");
        least = least.min(e);
    }
    let expected = if r.state.log.len() == rs.max_rounds {
        StopReason::MaxRounds
    } else {
        StopReason::Budget
    };
    assert_eq!(r.stopped, expected);
    let inf = infinite_causes(&cfg, &rs, &r.state, usize::MAX);
    let n_inf = r
        .state
        .bounds
        .iter()
        .filter(|(_, b)| b.eps.is_infinite())
        .count();
    assert!(n_inf > 0, "no infinite cell: the test shows nothing");
    assert_eq!(inf.len(), n_inf);
    for c in &inf {
        assert!(
            !c.unlabelled.is_empty() && c.cause.contains("min_cell"),
            "{c:?}"
        );
        for (x, status) in &c.unlabelled {
            let p = r.state.points.iter().find(|p| &p.x == x).expect("a corner");
            assert!(!p.labelled());
            assert_eq!(status, p.status.map_or("unsolved", |s| s.as_str()));
            assert!((0..2).all(|k| c.cell.0[k] <= x[k] && x[k] <= c.cell.1[k]));
        }
    }
    let report = RefineReport::new(&cfg, &rs, &r, r.stopped, "resume".into());
    assert_eq!(report.infinite.len(), n_inf.min(10));
    assert!(report.eps.is_infinite() && report.binding_cell.0.len() == 2);
}

/// The writing sink writes the first best round at once, whatever its pacing (`after` = 10⁹
/// s here): a run stopped during a long later round (an infeasible region's slow solves) still
/// leaves a certificate and a report saying it was running, and later rounds are paced.
#[test]
fn the_first_best_round_is_written_at_once() {
    let cfg = ProblemConfig {
        refine: quick_refine([5, 5], 200, 3, 1e-9),
        ..Default::default()
    };
    let dir = std::env::temp_dir().join(format!("ampc_refine_first_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let opts = RefineOptions {
        on_result: Some(writing_sink(
            &cfg,
            &dir,
            "resume",
            (1e9, true),
            std::sync::Arc::new(|_: &Model, _: &crate::certify::certificate::Certificate| None),
        )),
        ..Default::default()
    };
    let r = refine(&cfg, &cfg.refine, None, &opts).unwrap();
    assert!(r.state.log.len() >= 2, "one round shows no pacing");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join(REPORT_FILE)).unwrap()).unwrap();
    assert_eq!(report["stopped"], "running", "{report}");
    assert_eq!(
        report["rounds"], 1,
        "only the first round is written: {report}"
    );
    let cert: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("certificate.json")).unwrap()).unwrap();
    assert_eq!(cert["eps"].as_f64(), report["eps"].as_f64());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `refine.max_seconds` inside a round: round 0's sink waits until just before the budget
/// runs out, so it runs out while round 1's new corners are solved. The run stops there —
/// not at the end of round 1 as before — with round 0's certificate (every cell bounded and
/// finite, every corner labelled) and a checkpoint that keeps round 1's unsolved corners; a
/// resumed run solves them first and goes on from round 1.
#[test]
fn a_round_cut_by_the_wall_clock_budget_keeps_the_last_round_and_resumes() {
    use std::sync::Arc;
    use std::time::{Duration, Instant};
    let max = 12.0;
    let mut cfg = ProblemConfig {
        refine: quick_refine([13, 13], 5000, 6, 1e-9),
        ..Default::default()
    };
    cfg.refine.max_seconds = Some(max);
    // Three starts per corner (not the pilot's `warm` alone): round 1's solves must take
    // longer than the sink leaves of the budget.
    cfg.solver.starts = Some(crate::problem::solver::default_starts(false));
    let dir = std::env::temp_dir().join(format!("ampc_refine_cut_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let ck = dir.join("refine_state.bin");
    let t0 = Instant::now();
    let opts = RefineOptions {
        on_result: Some(RoundSink(Arc::new(move |r: &Refined, _| {
            if r.state.log.len() == 1 {
                let until = t0 + Duration::from_secs_f64(max - 0.01);
                std::thread::sleep(until.saturating_duration_since(Instant::now()));
            }
        }))),
        ..Default::default()
    };
    let r = refine(&cfg, &cfg.refine, Some(&ck), &opts).unwrap();
    let took = t0.elapsed().as_secs_f64();
    assert_eq!(
        r.stopped,
        StopReason::MaxSecondsInRound,
        "after {took:.1} s"
    );
    assert_eq!(r.state.log.len(), 1, "round 0's result");
    assert!(!r.state.bounds.is_empty());
    assert!(r.state.bounds.iter().all(|(_, b)| b.eps.is_finite()));
    for (n, _) in &r.state.bounds {
        assert!(r.state.nodes[*n].split.is_none());
        assert!(r.state.nodes[*n]
            .corners
            .iter()
            .all(|&c| r.state.points[c].labelled()));
    }
    assert!(
        took < max + 5.0,
        "stopped {took:.1} s after the start (budget {max} s)"
    );
    let bytes = std::fs::read(&ck).unwrap();
    let saved = RefineState::from_bytes(&bytes, &ck).unwrap();
    let unsolved = saved.points.iter().filter(|p| p.status.is_none()).count();
    assert!(
        !saved.finished && unsolved > 0,
        "the checkpoint keeps the unsolved corners"
    );
    // Resumed without a wall-clock budget: round 1 goes on, its corners solved first.
    cfg.refine.max_seconds = None;
    cfg.refine.max_rounds = 2;
    let resumed = refine(&cfg, &cfg.refine, Some(&ck), &RefineOptions::default()).unwrap();
    assert_eq!(resumed.state.log.len(), 2);
    assert!(resumed.state.log[1].solves > r.state.points.len());
    assert!(resumed.state.points.iter().all(|p| p.status.is_some()));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A cell whose corners are all unlabelled is excluded at once, at any size (it is never
/// split down to `refine.min_cell`); a mixed cell (some corners labelled) is excluded only at
/// that size; a corner not yet solved is not "unlabelled" (no exclusion before its solve).
#[test]
fn a_cell_without_any_label_is_excluded_at_once_a_mixed_one_only_when_small() {
    let cfg = ProblemConfig::default();
    // 3 × 3 points: cells 0 (lower left), 1, 2, 3 (row-major over the first axis).
    let (_, mut st, lat) = grid(&cfg, [3, 3]);
    let rs = crate::problem::RefineSettings::default();
    let ex = Exclusion::new(&rs, &lat.max);
    assert!(ex
        .min_size
        .iter()
        .zip(&st.nodes[0].size)
        .all(|(m, s)| m < s));
    // Before any solve: nothing excluded.
    assert!((0..4).all(|n| !st.all_unlabelled(n) && !st.excluded_by(n, &ex)));
    let dead: Vec<usize> = st.nodes[0].corners.clone();
    for (i, p) in st.points.iter_mut().enumerate() {
        if dead.contains(&i) {
            p.status = Some(SqpStatus::Infeasible);
        } else {
            p.status = Some(SqpStatus::Converged);
            p.u = vec![0.0];
            p.du = vec![0.0; 2];
        }
    }
    assert!(st.all_unlabelled(0) && st.excluded_by(0, &ex));
    assert_eq!(st.excluded_leaves_by(&ex), vec![0]);
    // Cells 1 and 2 share corners with cell 0 (mixed): not excluded at the initial size.
    for n in 1..4 {
        assert!(!st.all_unlabelled(n) && !st.excluded_by(n, &ex), "cell {n}");
    }
    // One corner of cell 0 not yet solved: cell 0 waits for it.
    st.points[dead[0]].status = None;
    assert!(!st.all_unlabelled(0) && !st.excluded_by(0, &ex));
    // A mixed cell at refine.min_cell is excluded (the earlier rule, unchanged).
    st.points[dead[0]].status = Some(SqpStatus::Infeasible);
    let big = Exclusion {
        infeasible: false,
        min_size: st.nodes[1].size.clone(),
    };
    assert!(st.excluded_by(1, &big) && !st.all_unlabelled(1));
}
