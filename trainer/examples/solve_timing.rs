//! Per-state timing of the OCP solver (cold start + KKT sensitivity, one thread): solves
//! every state of a states CSV (header `x1,…,xn`, as `trainer solve --states`) `reps` times
//! and prints one CSV row per state, `index,median_seconds,median_cpu_seconds,status,
//! iterations` (wall clock, and the thread's CPU time by `clock_gettime(CLOCK_THREAD_CPUTIME_ID)` on
//! 64-bit Linux, NaN elsewhere: on a loaded machine the CPU time is the fair figure),
//! then the medians over the states on stderr. Used by `tests/reference/ipopt_compare.py`
//! to time the same states as IPOPT, side by side.
//!
//! Usage: `cargo run --release -p trainer --example solve_timing -- CONFIG STATES.csv [reps]`
use std::time::Instant;
use trainer::mpc::law::MpcLaw;
use trainer::problem::ProblemConfig;

/// CPU time of this thread in seconds (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`, Linux
/// x86-64/aarch64), NaN elsewhere.
#[cfg(all(target_os = "linux", target_pointer_width = "64"))]
fn thread_cpu() -> f64 {
    #[repr(C)]
    struct Timespec {
        tv_sec: i64,
        tv_nsec: i64,
    }
    extern "C" {
        fn clock_gettime(clock: i32, tp: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut t = Timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a valid, writable timespec; the clock id is Linux's.
    #[allow(unsafe_code)]
    let rc = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut t) };
    if rc == 0 {
        t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
    } else {
        f64::NAN
    }
}

/// CPU time of this thread: not available on this platform.
#[cfg(not(all(target_os = "linux", target_pointer_width = "64")))]
fn thread_cpu() -> f64 {
    f64::NAN
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: solve_timing CONFIG STATES.csv [reps]");
        std::process::exit(2);
    }
    let cfg = ProblemConfig::load(std::path::Path::new(&args[1]))
        .unwrap_or_else(|e| panic!("{}: {e}", args[1]));
    let reps: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(5).max(1);
    let text = std::fs::read_to_string(&args[2]).unwrap_or_else(|e| panic!("{}: {e}", args[2]));
    let nx = cfg.system.nx();
    let states: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .enumerate()
        .map(|(i, l)| {
            let x: Vec<f64> = l
                .split(',')
                .map(|s| {
                    s.trim()
                        .parse()
                        .unwrap_or_else(|e| panic!("{} row {}: {e}", args[2], i + 2))
                })
                .collect();
            assert_eq!(
                x.len(),
                nx,
                "{} row {}: {nx} values expected",
                args[2],
                i + 2
            );
            x
        })
        .collect();
    let mut law = MpcLaw::new(&cfg);
    let (mut walls, mut cpus) = (Vec::new(), Vec::new());
    println!("index,median_seconds,median_cpu_seconds,status,iterations");
    for (i, x) in states.iter().enumerate() {
        let (mut t, mut c) = (Vec::with_capacity(reps), Vec::with_capacity(reps));
        let mut last = None;
        for _ in 0..reps {
            let (t0, c0) = (Instant::now(), thread_cpu());
            let (l, _) = std::hint::black_box(law.solve(x, None));
            c.push(thread_cpu() - c0);
            t.push(t0.elapsed().as_secs_f64());
            last = Some(l);
        }
        let (m, mc) = (median(&mut t), median(&mut c));
        walls.push(m);
        cpus.push(mc);
        let l = last.expect("reps >= 1");
        println!(
            "{i},{m:e},{mc:e},{},{}",
            l.status.as_str(),
            l.info.iterations
        );
    }
    eprintln!(
        "{}: {} states, median {:.1} µs wall, {:.1} µs CPU per cold solve + sensitivity ({reps} repetitions each)",
        cfg.name,
        states.len(),
        median(&mut walls) * 1e6,
        median(&mut cpus) * 1e6
    );
}
