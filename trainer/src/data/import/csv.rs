//! The CSV reader of `trainer import`: a table of states and labels from another solver →
//! rows `(x, u, ∂u/∂x, status, …)` checked against the problem's dimensions and domain X.
//!
//! **Column rule** (header on the first line, names trimmed, surrounding `"` removed):
//! - an index column first: an empty name (pandas' `df.to_csv()` default), `index` (ampc's
//!   own `dataset.csv`) or `Unnamed: 0` — read and ignored (records are numbered by row);
//! - `x1..xn` (1-based, as in `dataset.csv`, `solve` and `eval`) or the problem's state
//!   names (pendulum `theta`, `omega`): required, each once;
//! - `u1..um` or the problem's input names: required;
//! - `du{j}_dx{i}` (∂u_j/∂x_i): all n·m of them or none;
//! - optional: `status` (`converged`, `soft`, `infeasible`, `max_iterations`,
//!   `numerical_failure`; default `converged`), `cost`, `max_slack`, `degenerate`
//!   (empty, `weakly_active`, `singular`), `iterations`, `kkt` — the columns of
//!   `dataset.csv`, so an ampc export imports back unchanged;
//! - any other name is an error naming it.
//!
//! A labelled row (status `converged`/`soft`) must have finite x, u and (when present,
//! unless `degenerate`) ∂u/∂x; an unlabelled row finite x. Every x must lie in X. Errors
//! name the file, the line (1-based) and the column.

use crate::data::dataset::Record;
use crate::mpc::sensitivity::Degeneracy;
use crate::mpc::sqp::SqpStatus;

/// What a column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Col {
    Index,
    X(usize),
    U(usize),
    Du(usize, usize),
    Status,
    Cost,
    MaxSlack,
    Degenerate,
    Iterations,
    Kkt,
}

/// A parse or check failure: `file:line: column `name`: reason`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}:{line}: {}{reason}", column.as_ref().map(|c| format!("column `{c}`: ")).unwrap_or_default())]
pub struct CsvError {
    /// The file.
    pub file: String,
    /// 1-based line.
    pub line: usize,
    /// The column at fault, if one is.
    pub column: Option<String>,
    /// What is wrong.
    pub reason: String,
}

/// The parsed table.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// One record per data row, `index` = row number (0-based).
    pub records: Vec<Record>,
    /// 1-based file line of each record (for error messages).
    pub lines: Vec<usize>,
    /// Whether the Jacobian columns were present.
    pub jacobian: bool,
}

/// A value in an error message: at most 80 characters, in backquotes ([`crate::io::quote`]).
fn quote(v: &str) -> String {
    crate::io::quote(v)
}

/// A column name in an error message: at most 80 characters (then `…`).
fn short(c: &str) -> String {
    match c.char_indices().nth(80) {
        Some((at, _)) => format!("{}…", &c[..at]),
        None => c.to_string(),
    }
}

fn unquote(s: &str) -> &str {
    let t = s.trim();
    t.strip_prefix('"')
        .and_then(|t| t.strip_suffix('"'))
        .unwrap_or(t)
}

/// Maps the header's names to columns (see the module doc).
fn columns(
    header: &[&str],
    names: (&[String], &[String]),
    nx: usize,
    nu: usize,
    err: &dyn Fn(Option<&str>, String) -> CsvError,
) -> Result<Vec<Col>, CsvError> {
    let (xnames, unames) = names;
    let mut cols = Vec::with_capacity(header.len());
    for (k, raw) in header.iter().enumerate() {
        let name = unquote(raw);
        let num = |p: &str, n: usize| -> Option<usize> {
            let i: usize = name.strip_prefix(p)?.parse().ok()?;
            (1..=n).contains(&i).then(|| i - 1)
        };
        let col = if k == 0 && matches!(name, "" | "index" | "Unnamed: 0") {
            Col::Index
        } else if let Some(i) = num("x", nx).or_else(|| xnames.iter().position(|s| s == name)) {
            Col::X(i)
        } else if let Some(j) = num("u", nu).or_else(|| unames.iter().position(|s| s == name)) {
            Col::U(j)
        } else if let Some((j, i)) = name
            .strip_prefix("du")
            .and_then(|r| r.split_once("_dx"))
            .and_then(|(j, i)| Some((j.parse::<usize>().ok()?, i.parse::<usize>().ok()?)))
            .filter(|&(j, i)| (1..=nu).contains(&j) && (1..=nx).contains(&i))
        {
            Col::Du(j - 1, i - 1)
        } else {
            match name {
                "status" => Col::Status,
                "cost" => Col::Cost,
                "max_slack" => Col::MaxSlack,
                "degenerate" => Col::Degenerate,
                "iterations" => Col::Iterations,
                "kkt" => Col::Kkt,
                _ => {
                    return Err(err(
                        Some(name),
                        format!(
                            "unknown column for a problem with {nx} states and {nu} inputs \
                             (expected x1..x{nx}, u1..u{nu}, optional du1_dx1..du{nu}_dx{nx}, \
                             status, cost, max_slack, degenerate, iterations, kkt, and an \
                             optional leading index column)"
                        ),
                    ))
                }
            }
        };
        if cols.contains(&col) {
            return Err(err(Some(name), "given twice".into()));
        }
        cols.push(col);
    }
    for i in 0..nx {
        if !cols.contains(&Col::X(i)) {
            return Err(err(
                None,
                format!("missing column x{} (the problem has {nx} states)", i + 1),
            ));
        }
    }
    for j in 0..nu {
        if !cols.contains(&Col::U(j)) {
            return Err(err(
                None,
                format!("missing column u{} (the problem has {nu} inputs)", j + 1),
            ));
        }
    }
    let n_du = cols.iter().filter(|c| matches!(c, Col::Du(..))).count();
    if n_du != 0 && n_du != nx * nu {
        return Err(err(
            None,
            format!(
                "{n_du} of the {} Jacobian columns du{{j}}_dx{{i}}: give all or none",
                nx * nu
            ),
        ));
    }
    Ok(cols)
}

fn parse_status(s: &str) -> Option<SqpStatus> {
    Some(match s {
        "" | "converged" => SqpStatus::Converged,
        "soft" => SqpStatus::Soft,
        "infeasible" => SqpStatus::Infeasible,
        "max_iterations" => SqpStatus::MaxIterations,
        "numerical_failure" => SqpStatus::NumericalFailure,
        _ => return None,
    })
}

/// Parses and checks the CSV `text` (from `file`) for a problem with the given state and
/// input names (`names`: the problem's, used as aliases) and domain X = [lo, hi].
pub fn parse(
    text: &str,
    file: &str,
    names: (&[String], &[String]),
    lo: &[f64],
    hi: &[f64],
    nu: usize,
) -> Result<Table, CsvError> {
    let nx = lo.len();
    let err_at = |line: usize, col: Option<&str>, reason: String| CsvError {
        file: file.to_string(),
        line,
        column: col.map(short),
        reason,
    };
    // A UTF-8 byte-order mark (as Excel writes it) is not part of the first column's name.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.strip_suffix('\r').unwrap_or(l)))
        .filter(|(_, l)| !l.trim().is_empty());
    let (hl, header) = lines
        .next()
        .ok_or_else(|| err_at(1, None, "empty file (expected a header line)".into()))?;
    let head: Vec<&str> = header.split(',').collect();
    let cols = columns(&head, names, nx, nu, &|c, r| err_at(hl, c, r))?;
    let jacobian = cols.iter().any(|c| matches!(c, Col::Du(..)));
    // Widened X: states written with `{:?}` round-trip exactly, a tolerance of 1e-12 of the
    // width only absorbs another tool's last-digit rounding.
    let slack: Vec<f64> = lo.iter().zip(hi).map(|(l, h)| 1e-12 * (h - l)).collect();
    let mut records = Vec::new();
    let mut at = Vec::new();
    for (ln, line) in lines {
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != cols.len() {
            return Err(err_at(
                ln,
                None,
                format!("{} columns, the header has {}", fields.len(), cols.len()),
            ));
        }
        let err = |c: Option<&str>, reason: String| err_at(ln, c, reason);
        let index = records.len() as u64;
        let r = read_row(&fields, &cols, &head, (nx, nu), index, &err)?;
        check_row(&r, &cols, &head, (lo, hi), &slack, jacobian, &err)?;
        records.push(r);
        at.push(ln);
    }
    if records.is_empty() {
        return Err(err_at(hl, None, "no data rows after the header".into()));
    }
    Ok(Table {
        records,
        lines: at,
        jacobian,
    })
}

/// Reads one data row's `fields` (one per column of `cols`, named by `head`) into the
/// record numbered `index`; missing values are NaN. `err` makes the error of the row's
/// line naming a column.
fn read_row(
    fields: &[&str],
    cols: &[Col],
    head: &[&str],
    (nx, nu): (usize, usize),
    index: u64,
    err: &dyn Fn(Option<&str>, String) -> CsvError,
) -> Result<Record, CsvError> {
    let name = |k: usize| unquote(head[k]).to_string();
    let mut r = Record {
        index,
        x: vec![f64::NAN; nx],
        u: vec![f64::NAN; nu],
        du_dx: vec![f64::NAN; nx * nu],
        cost: f64::NAN,
        status: SqpStatus::Converged,
        iterations: 0,
        kkt: f64::NAN,
        degeneracy: None,
        max_slack: 0.0,
        seq: Vec::new(),
    };
    for (k, (col, raw)) in cols.iter().zip(fields).enumerate() {
        let v = unquote(raw);
        let num = || -> Result<f64, CsvError> {
            // Empty fields are missing values (pandas writes NaN as an empty field).
            if v.is_empty() {
                return Ok(f64::NAN);
            }
            v.parse::<f64>()
                .map_err(|_| err(Some(&name(k)), format!("{} is not a number", quote(v))))
        };
        match *col {
            Col::Index => {}
            Col::X(i) => r.x[i] = num()?,
            Col::U(j) => r.u[j] = num()?,
            Col::Du(j, i) => r.du_dx[j * nx + i] = num()?,
            Col::Cost => r.cost = num()?,
            Col::MaxSlack => r.max_slack = num()?,
            Col::Kkt => r.kkt = num()?,
            Col::Iterations => {
                r.iterations = if v.is_empty() {
                    0
                } else {
                    v.parse()
                        .map_err(|_| err(Some(&name(k)), format!("{} is not a count", quote(v))))?
                }
            }
            Col::Status => {
                r.status = parse_status(v).ok_or_else(|| {
                    err(
                        Some(&name(k)),
                        format!(
                            "unknown status {} (converged, soft, infeasible, \
                             max_iterations, numerical_failure)",
                            quote(v)
                        ),
                    )
                })?
            }
            Col::Degenerate => {
                r.degeneracy = match v {
                    "" => None,
                    // dataset.csv does not keep the count: 0 stands for "unknown".
                    "weakly_active" => Some(Degeneracy::WeaklyActive(0)),
                    "singular" => Some(Degeneracy::Singular),
                    _ => {
                        return Err(err(
                            Some(&name(k)),
                            format!("{} is not empty, weakly_active or singular", quote(v)),
                        ))
                    }
                }
            }
        }
    }
    Ok(r)
}

/// Checks a row read by [`read_row`]: x finite and in X = [lo, hi] widened by `slack`; a
/// labelled row's u finite, and its ∂u/∂x too when the table has them (`jacobian`) and
/// the row is not `degenerate`.
fn check_row(
    r: &Record,
    cols: &[Col],
    head: &[&str],
    (lo, hi): (&[f64], &[f64]),
    slack: &[f64],
    jacobian: bool,
    err: &dyn Fn(Option<&str>, String) -> CsvError,
) -> Result<(), CsvError> {
    let nx = lo.len();
    let name = |k: usize| unquote(head[k]).to_string();
    let col_of = |c: Col| cols.iter().position(|&d| d == c).map(name);
    for i in 0..nx {
        let v = r.x[i];
        if !v.is_finite() {
            return Err(err(
                col_of(Col::X(i)).as_deref(),
                format!("state x{} = {v} is not finite", i + 1),
            ));
        }
        if v < lo[i] - slack[i] || v > hi[i] + slack[i] {
            return Err(err(
                col_of(Col::X(i)).as_deref(),
                format!(
                    "state x{} = {v} is outside the problem's domain X: [{}, {}]",
                    i + 1,
                    lo[i],
                    hi[i]
                ),
            ));
        }
    }
    if r.status.is_labelled() {
        if let Some(j) = r.u.iter().position(|v| !v.is_finite()) {
            return Err(err(
                col_of(Col::U(j)).as_deref(),
                format!(
                    "label u{} = {} is not finite in a row of status {} (mark unlabelled \
                     rows with status infeasible / numerical_failure)",
                    j + 1,
                    r.u[j],
                    r.status.as_str()
                ),
            ));
        }
        if jacobian && r.degeneracy.is_none() {
            if let Some(k) = r.du_dx.iter().position(|v| !v.is_finite()) {
                let (j, i) = (k / nx, k % nx);
                return Err(err(
                    col_of(Col::Du(j, i)).as_deref(),
                    format!(
                        "Jacobian label du{}_dx{} = {} is not finite (mark the row \
                         `degenerate` to drop its Jacobian)",
                        j + 1,
                        i + 1,
                        r.du_dx[k]
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Relative tolerance of the input-bound check of labels: a label u_j is accepted when
/// `u_lo_j − tol_j ≤ u_j ≤ u_hi_j + tol_j`, `tol_j = U_RTOL·max(1, |bound|)` (another solver
/// may meet a bound up to its own constraint tolerance, e.g. IPOPT's relaxation 1e-8).
pub const U_RTOL: f64 = 1e-6;

/// Checks every labelled row's inputs against U = [u_lo, u_hi] (the OCP's bounds on u₀;
/// infinite entries: no bound) with the tolerance [`U_RTOL`]; the error names the file, the
/// line and the value.
pub fn check_inputs(t: &Table, file: &str, u_lo: &[f64], u_hi: &[f64]) -> Result<(), CsvError> {
    let tol = |b: f64| U_RTOL * b.abs().max(1.0);
    for (r, &line) in t.records.iter().zip(&t.lines) {
        if !r.status.is_labelled() {
            continue;
        }
        for (j, &u) in r.u.iter().enumerate() {
            let (lo, hi) = (u_lo[j], u_hi[j]);
            if u < lo - tol(lo) || u > hi + tol(hi) {
                return Err(CsvError {
                    file: file.to_string(),
                    line,
                    column: None,
                    reason: format!(
                        "label u{} = {u} is outside the problem's input bounds U: [{lo}, {hi}] \
                         (tolerance {U_RTOL:e}·max(1, |bound|)); a label must be an input the \
                         MPC can apply",
                        j + 1
                    ),
                });
            }
        }
    }
    Ok(())
}
