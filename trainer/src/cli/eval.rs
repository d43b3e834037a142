//! `trainer eval`: evaluates a trained model (`--model`) at every state of a states CSV
//! (`--states`, header `x1,…,xn`) and writes its outputs and Jacobians as CSV (`--out`).

use super::common::{csv_numbers, jacobian_header, read_states};
use anyhow::Result;
use std::path::Path;

pub(super) fn execute(model: &Path, states: &Path, out: &Path) -> Result<()> {
    let m = super::common::load_model(model)?;
    let (nx, nu) = (m.mlp.nx(), m.mlp.nu());
    let xs = read_states(states, nx)?;
    let mut s = jacobian_header(nx, nu).join(",");
    s.push('\n');
    let mut ws = trainer::learn::mlp::Workspace::default();
    let (mut u, mut jac) = (vec![0.0; nu], vec![0.0; nu * nx]);
    for x in &xs {
        m.mlp.eval(x, &mut u, &mut jac, &mut ws);
        s += &csv_numbers(x.iter().chain(&u).chain(&jac));
        s.push('\n');
    }
    trainer::io::write_atomic(out, s.as_bytes())?;
    Ok(())
}
