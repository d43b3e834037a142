//! Custom plants: the pendulum written as a user's struct is bit-identical to the built-in;
//! problem files with a custom plant round-trip with the same hash only through a program
//! that has the plant; the hash tells apart plants under one name (version, parameters,
//! equations); parameters in the file rebuild the plant; errors name the plant and the key.

use super::super::test_plants::oscillator;
use super::super::{Discrete, DualNum, Dynamics, Pendulum, System};
use super::*;
use crate::problem::{ConfigError, ProblemConfig};

/// The paper's pendulum written again as a user would (not the built-in type).
#[derive(Debug, Clone, Serialize, Deserialize)]
struct MyPendulum {
    m: f64,
    l: f64,
    g: f64,
}

const ONE: MyPendulum = MyPendulum {
    m: 1.0,
    l: 1.0,
    g: 9.81,
};

impl Dynamics for MyPendulum {
    const NX: usize = 2;
    const NU: usize = 1;
    fn rhs<D: DualNum<Primitive = f64> + Copy>(&self, x: &[D], u: &[D], dx: &mut [D]) {
        dx[0] = x[1];
        dx[1] = u[0] * (1.0 / (self.m * self.l * self.l))
            - (x[0] + std::f64::consts::PI).sin() * (self.g / self.l);
    }
}

/// Same name, fields and version as [`MyPendulum`], other equations (damped).
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Impostor {
    m: f64,
    l: f64,
    g: f64,
}

impl Dynamics for Impostor {
    const NX: usize = 2;
    const NU: usize = 1;
    fn rhs<D: DualNum<Primitive = f64> + Copy>(&self, x: &[D], u: &[D], dx: &mut [D]) {
        dx[0] = x[1];
        dx[1] = u[0] * (1.0 / (self.m * self.l * self.l))
            - (x[0] + std::f64::consts::PI).sin() * (self.g / self.l)
            - x[1] * 0.01;
    }
}

/// 15 states and 2 inputs: one more than the derivatives are compiled for.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct TooBig {}

impl Dynamics for TooBig {
    const NX: usize = 15;
    const NU: usize = 2;
    fn rhs<D: DualNum<Primitive = f64> + Copy>(&self, _: &[D], _: &[D], dx: &mut [D]) {
        dx.fill(D::from(0.0));
    }
}

fn pendulum(version: &str, p: MyPendulum) -> CustomPlant {
    CustomPlant::new("my_pendulum", version, p).unwrap_or_else(|e| panic!("{e}"))
}

/// The default (paper's) problem with its plant replaced.
fn problem(plant: CustomPlant) -> ProblemConfig {
    let cfg = ProblemConfig {
        system: System::Custom(plant),
        ..Default::default()
    };
    cfg.validate().unwrap_or_else(|e| panic!("{e}"));
    cfg
}

fn parse_err(r: Result<ProblemConfig, ConfigError>) -> String {
    match r {
        Ok(c) => panic!("read {c:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_custom_pendulum_is_bit_identical_to_the_built_in() {
    for substeps in [1, 3] {
        let a = Discrete::new(System::Pendulum(Pendulum::default()), 0.05, substeps);
        let b = Discrete::new(System::Custom(pendulum("1", ONE)), 0.05, substeps);
        for k in 0..200 {
            let t = k as f64 * 0.37;
            let (x, u, lam) = (
                [t.sin() * 6.0, t.cos()],
                [15.0 * (1.3 * t).sin()],
                [0.3, -t],
            );
            let run = |d: &Discrete| {
                let (mut f, mut jx, mut ju, mut h, mut s, mut r) = (
                    vec![0.0; 2],
                    vec![0.0; 4],
                    vec![0.0; 2],
                    vec![0.0; 9],
                    vec![0.0; 2],
                    vec![0.0; 2],
                );
                d.linearize(&x, &u, &mut f, &mut jx, &mut ju);
                d.lagrangian_hessian(&x, &u, &lam, &mut h);
                d.step(&x, &u, &mut s);
                d.system.rhs(&x, &u, &mut r);
                [f, jx, ju, h, s, r]
                    .concat()
                    .into_iter()
                    .map(f64::to_bits)
                    .collect::<Vec<_>>()
            };
            assert_eq!(run(&a), run(&b), "x {x:?} u {u:?}");
        }
    }
}

#[test]
fn custom_problems_round_trip_only_through_a_program_that_has_the_plant() {
    let proto = pendulum("1", ONE);
    let cfg = problem(proto.clone());
    let text = cfg.to_toml_string().unwrap();
    for key in [
        "kind = \"custom\"",
        "name = \"my_pendulum\"",
        "version = \"1\"",
        "fingerprint = ",
        "[system.parameters]",
        "g = 9.81",
    ] {
        assert!(text.contains(key), "{key} not in\n{text}");
    }
    let back = ProblemConfig::from_toml_str_with(&text, "p.toml", &[proto]).unwrap();
    assert_eq!(back, cfg);
    assert_eq!(back.problem_hash(), cfg.problem_hash());
    assert_ne!(cfg.problem_hash(), ProblemConfig::default().problem_hash());
    // Without the plant: an error naming it, never a plant of another kind.
    let e = parse_err(ProblemConfig::from_toml_str(&text, "p.toml"));
    assert!(
        e.contains("custom plant `my_pendulum`") && e.contains("cannot rebuild it"),
        "{e}"
    );
    assert!(
        e.contains("p.toml") && e.contains("it has no custom plants"),
        "{e}"
    );
    let other = CustomPlant::new(
        "oscillator",
        "1",
        super::super::test_plants::Oscillator::default(),
    )
    .unwrap();
    let e = parse_err(ProblemConfig::from_toml_str_with(&text, "p.toml", &[other]));
    assert!(e.contains("its custom plants are `oscillator`"), "{e}");
    // The plants given to one read are not kept for the next.
    assert!(ProblemConfig::from_toml_str(&text, "p.toml").is_err());
}

#[test]
fn the_hash_tells_plants_under_one_name_apart() {
    let base = problem(pendulum("1", ONE));
    let heavier = problem(pendulum("1", MyPendulum { m: 1.5, ..ONE }));
    let v2 = problem(pendulum("2", ONE));
    let impostor = problem(
        CustomPlant::new(
            "my_pendulum",
            "1",
            Impostor {
                m: 1.0,
                l: 1.0,
                g: 9.81,
            },
        )
        .unwrap(),
    );
    let hashes = [&base, &heavier, &v2, &impostor].map(|c| c.problem_hash());
    for i in 0..4 {
        for j in 0..i {
            assert_ne!(hashes[i], hashes[j], "{i} {j}");
        }
    }
    let text = base.to_toml_string().unwrap();
    // Another version of the plant: the file is refused at `system.version`.
    let e = parse_err(ProblemConfig::from_toml_str_with(
        &text,
        "p.toml",
        &[pendulum("2", ONE)],
    ));
    assert!(
        e.contains("`system.version`") && e.contains("version 1"),
        "{e}"
    );
    // Other equations under the same name and version: refused at `system.fingerprint`.
    let imp = CustomPlant::new(
        "my_pendulum",
        "1",
        Impostor {
            m: 1.0,
            l: 1.0,
            g: 9.81,
        },
    )
    .unwrap();
    let e = parse_err(ProblemConfig::from_toml_str_with(
        &text,
        "p.toml",
        std::slice::from_ref(&imp),
    ));
    assert!(e.contains("`system.fingerprint`"), "{e}");
    // A file written by hand, without a fingerprint, is read with the plant the program has.
    let hand = text
        .lines()
        .filter(|l| !l.starts_with("fingerprint"))
        .collect::<Vec<_>>()
        .join("\n");
    let read = ProblemConfig::from_toml_str_with(&hand, "p.toml", &[imp]).unwrap();
    assert_eq!(read.problem_hash(), impostor.problem_hash());
}

#[test]
fn parameters_in_the_file_rebuild_the_plant() {
    let proto = pendulum("1", ONE);
    let text = problem(proto.clone()).to_toml_string().unwrap();
    // The file sets m; l and g come from the prototype.
    let heavy = text.replace("m = 1.0", "m = 2");
    assert_ne!(heavy, text);
    let cfg = ProblemConfig::from_toml_str_with(&heavy, "p.toml", std::slice::from_ref(&proto));
    // The fingerprint written for m = 1 does not match m = 3: the file is refused ...
    assert!(parse_err(cfg).contains("`system.fingerprint`"));
    // ... and without it the plant is rebuilt with m = 2.
    let heavy: String = heavy
        .lines()
        .filter(|l| !l.starts_with("fingerprint"))
        .map(|l| format!("{l}\n"))
        .collect();
    let cfg =
        ProblemConfig::from_toml_str_with(&heavy, "p.toml", std::slice::from_ref(&proto)).unwrap();
    let want = problem(pendulum("1", MyPendulum { m: 2.0, ..ONE }));
    assert_eq!(cfg.problem_hash(), want.problem_hash());
    let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
    cfg.system.rhs(&[0.1, 0.2], &[1.0], &mut a);
    want.system.rhs(&[0.1, 0.2], &[1.0], &mut b);
    assert_eq!(a, b);
    assert!((a[1] - (0.5 - (0.1f64 + std::f64::consts::PI).sin() * 9.81)).abs() < 1e-12);
    // A key the struct does not have, and a value of the wrong type.
    let e = parse_err(ProblemConfig::from_toml_str_with(
        &heavy.replace("m = 2", "m = 2\nmass = 3.0"),
        "p.toml",
        std::slice::from_ref(&proto),
    ));
    assert!(
        e.contains("`system.parameters.mass`") && e.contains("g, l, m"),
        "{e}"
    );
    let e = parse_err(ProblemConfig::from_toml_str_with(
        &heavy.replace("m = 2", "m = \"heavy\""),
        "p.toml",
        &[proto],
    ));
    assert!(e.contains("`system.parameters`"), "{e}");
}

#[test]
fn sizes_names_and_the_mass_are_checked() {
    let e = CustomPlant::new("big", "1", TooBig {}).unwrap_err();
    assert_eq!(e.key, "system");
    assert!(e.reason.contains("at most 16"), "{e}");
    let e = CustomPlant::new("", "1", ONE).unwrap_err();
    assert_eq!(e.key, "system.name");
    let e = pendulum("1", ONE).with_names(&["a"], &["u"]).unwrap_err();
    assert_eq!(e.key, "system.states");
    let p = pendulum("1", ONE).with_names(&["θ", "ω"], &["τ"]).unwrap();
    assert_eq!(p.state_names(), ["θ", "ω"]);
    assert_eq!(pendulum("1", ONE).input_names(), ["u1"]);
    // Mass mismatch scales `m` through the parameter record.
    let sys = System::Custom(pendulum("1", ONE));
    let scaled = sys.with_mass_scaled(1.25).unwrap();
    assert_eq!(
        scaled,
        System::Custom(pendulum("1", MyPendulum { m: 1.25, ..ONE }))
    );
    assert_eq!(oscillator().with_mass_scaled(1.25), None, "no mass, no m");
    assert_eq!(sys.name(), "my_pendulum");
    assert_eq!(sys.custom_plants().len(), 1);
}

/// Timing of `Discrete::linearize` and `lagrangian_hessian`: the built-in pendulum vs the
/// same plant as a custom plant (`Arc<dyn ErasedPlant>` + `by_nz!`), interleaved rounds
/// (`cargo test --release -p trainer --lib custom_plant_timing -- --ignored --nocapture`).
#[test]
#[ignore]
fn custom_plant_timing() {
    let a = Discrete::new(System::Pendulum(Pendulum::default()), 0.05, 1);
    let b = Discrete::new(System::Custom(pendulum("1", ONE)), 0.05, 1);
    let once = |d: &Discrete, hess: bool| {
        let n = 100_000;
        let (mut f, mut jx, mut ju, mut h) = ([0.0; 2], [0.0; 4], [0.0; 2], [0.0; 9]);
        let t0 = std::time::Instant::now();
        let mut acc = 0.0;
        for k in 0..n {
            let x = [k as f64 * 1e-6, 0.5];
            if hess {
                d.lagrangian_hessian(&x, &[1.0], &[0.3, -0.2], &mut h);
                acc += h[4];
            } else {
                d.linearize(&x, &[1.0], &mut f, &mut jx, &mut ju);
                acc += jx[2];
            }
        }
        std::hint::black_box(acc);
        t0.elapsed().as_nanos() as f64 / n as f64
    };
    let rounds = 21;
    let mut t = vec![vec![]; 4];
    for _ in 0..rounds {
        for (i, (d, hess)) in [(&a, false), (&b, false), (&a, true), (&b, true)]
            .into_iter()
            .enumerate()
        {
            t[i].push(once(d, hess));
        }
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let m: Vec<f64> = t.iter_mut().map(med).collect();
    eprintln!(
        "linearize: built-in {:.1} ns, custom {:.1} ns; lagrangian_hessian: built-in {:.1} ns, \
         custom {:.1} ns (medians of {rounds} interleaved rounds of 100k)",
        m[0], m[1], m[2], m[3]
    );
}
