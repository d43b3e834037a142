//! How often the MPC's own optimal sequence passes the safe controller's online check (issue
//! 41 §6): for the first `n` starts of the safety study (`study::safety::start`), solve the MPC
//! of the problem as `trainer run` labels it (`pipeline::labelling_problem`: with
//! `[closed_loop] safety = true` it imposes the check's terminal ingredients) and hand its
//! sequence to the emulated `SafeController::init_with`. Prints the counts, and why the
//! sequences of hard optima fail (state box / terminal set / input box).
//!
//! `cargo run --release -p trainer --example safe_mpc_check -- configs/cartpole_safe.toml 400 [plain]`
//! (`plain`: the problem file's own OCP, without the online check).

use rayon::prelude::*;
use trainer::deploy::safe_emulation::{EmulatedPlant, SafeEmulation};
use trainer::mpc::law::MpcLaw;
use trainer::mpc::sqp::SqpStatus;
use trainer::problem::ProblemConfig;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .ok_or("usage: safe_mpc_check CONFIG [N] [plain]")?;
    let n: u64 = args.get(2).map_or(Ok(400), |s| s.parse())?;
    let mut base = ProblemConfig::load(std::path::Path::new(path))?;
    if args.get(3).map(String::as_str) == Some("plain") {
        base.closed_loop.safety_terminal = false;
    }
    let t = std::time::Instant::now();
    let cfg = trainer::pipeline::labelling_problem(&base)?;
    let (plant, _) = EmulatedPlant::new(&base)?;
    println!(
        "{}: online check {} ({:.1} s); margins m_s {:e}, m_f {:e}",
        cfg.name,
        if cfg.ocp.online_check.is_some() {
            "imposed on the MPC"
        } else {
            "not imposed"
        },
        t.elapsed().as_secs_f64(),
        plant.margins.0,
        plant.margins.1
    );
    let (nx, nu, h) = (cfg.system.nx(), cfg.system.nu(), cfg.ocp.horizon);
    let t = std::time::Instant::now();
    // (status, passes, terminal violation + m_f, max stage violation + m_s, inputs inside U)
    let out: Vec<(SqpStatus, bool, f32, f32, bool)> = (0..n)
        .into_par_iter()
        .map_init(
            || MpcLaw::new(&cfg),
            |law, i| {
                let x0 = trainer::study::safety::start(&cfg, i);
                let (l, _) = law.solve(&x0, None);
                if !l.status.is_labelled() || l.seq.len() != h * nu {
                    return (l.status, false, f32::NAN, f32::NAN, false);
                }
                let x32: Vec<f32> = x0.iter().map(|v| *v as f32).collect();
                let rows: Vec<Vec<f32>> = l
                    .seq
                    .chunks(nu)
                    .map(|r| r.iter().map(|v| *v as f32).collect())
                    .collect();
                let mut emu = SafeEmulation::new(&plant, h);
                let pass = emu.init_with(&x32, &rows).is_some();
                let (mut xk, mut gs, mut inside) = (x32.clone(), f32::NEG_INFINITY, true);
                for (k, u) in rows.iter().enumerate() {
                    inside &= plant.project_input(u) == *u;
                    gs = gs.max(plant.stage_violation(k, &xk, u) + plant.margins.0);
                    xk = plant.step(&xk, u);
                }
                let gf = plant.terminal_violation(&xk) + plant.margins.1;
                (l.status, pass, gf, gs, inside)
            },
        )
        .collect();
    let _ = nx;
    let hard: Vec<_> = out.iter().filter(|o| o.0 == SqpStatus::Converged).collect();
    let soft = out.iter().filter(|o| o.0 == SqpStatus::Soft).count();
    let pass_hard = hard.iter().filter(|o| o.1).count();
    let pass_all = out.iter().filter(|o| o.1).count();
    println!(
        "{n} starts ({:.1} s): {} hard optima, {soft} soft labels, {} unlabelled; the sequence \
         passes the check at {pass_hard} of the hard optima ({:.2} %) and {pass_all} starts in all",
        t.elapsed().as_secs_f64(),
        hard.len(),
        n as usize - hard.len() - soft,
        100.0 * pass_hard as f64 / hard.len().max(1) as f64
    );
    let fails: Vec<_> = hard.iter().filter(|o| !o.1).collect();
    println!(
        "hard optima failing: terminal set/box {} , stage box {}, inputs outside U {}",
        fails.iter().filter(|o| o.2.is_nan() || o.2 > 0.0).count(),
        fails.iter().filter(|o| o.3.is_nan() || o.3 > 0.0).count(),
        fails.iter().filter(|o| !o.4).count()
    );
    let worst = fails.iter().map(|o| o.2).fold(f32::NEG_INFINITY, f32::max);
    if !fails.is_empty() {
        println!("largest terminal g_N + m_f among them: {worst:e}");
    }
    Ok(())
}
