//! The states CSV that `trainer solve` and `trainer eval` read: a header `x1,…,xn`, then one
//! finite state x ∈ ℝⁿ per row (blank lines skipped). [`parse_states`] owns the format; every
//! error names the file, the line and (for a bad number) the column.

/// A states CSV that cannot be read; the message names the file, line and column at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct StatesError(pub String);

/// Parses the states CSV `text` (from `origin`) for a problem with `nx` states (header
/// `x1,…,xn`); [`parse_states_named`] also takes the problem's state names.
pub fn parse_states(text: &str, origin: &str, nx: usize) -> Result<Vec<Vec<f64>>, StatesError> {
    parse_states_named(text, origin, nx, &[])
}

/// Parses the states CSV `text` (from `origin`) for a problem with `nx` states named `names`
/// (empty: unnamed). The header names each state once, as `x{i}` (1-based) or by its name
/// (as `trainer import` reads them), in any order; a UTF-8 byte-order mark (as Excel
/// writes) is skipped; a bad field is quoted with at most 80 characters.
pub fn parse_states_named(
    text: &str,
    origin: &str,
    nx: usize,
    names: &[String],
) -> Result<Vec<Vec<f64>>, StatesError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        return Err(StatesError(format!(
            "{origin}: empty file (expected a header x1,…,x{nx})"
        )));
    };
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let expected: Vec<String> = (1..=nx).map(|i| format!("x{i}")).collect();
    let index = |c: &str| {
        let c = c
            .strip_prefix('"')
            .and_then(|c| c.strip_suffix('"'))
            .unwrap_or(c);
        expected
            .iter()
            .position(|e| e == c)
            .or_else(|| names.iter().position(|n| n == c))
    };
    // perm[k]: the state of column k.
    let perm: Option<Vec<usize>> = cols.iter().map(|c| index(c)).collect();
    let valid = perm.as_ref().is_some_and(|p| {
        let mut seen = vec![false; nx];
        p.len() == nx && p.iter().all(|&i| !std::mem::replace(&mut seen[i], true))
    });
    let Some(perm) = perm.filter(|_| valid) else {
        let named = if names.len() == nx {
            format!(" or `{}`", names.join(","))
        } else {
            String::new()
        };
        return Err(StatesError(format!(
            "{origin}:1: header must be `{}`{named} for this problem ({nx} states), each state \
             once, got {}",
            expected.join(","),
            crate::io::quote(header.trim())
        )));
    };
    let mut out = Vec::new();
    for (ln, line) in lines {
        let vals: Vec<&str> = line.split(',').map(str::trim).collect();
        if vals.len() != nx {
            return Err(StatesError(format!(
                "{origin}:{}: expected {nx} columns, got {}",
                ln + 1,
                vals.len()
            )));
        }
        let mut x = vec![0.0; nx];
        for (k, v) in vals.iter().enumerate() {
            let i = perm[k];
            let f: f64 = v.parse().map_err(|e| {
                StatesError(format!(
                    "{origin}:{}: x{} = {} is not a number: {e}",
                    ln + 1,
                    i + 1,
                    crate::io::quote(v)
                ))
            })?;
            if !f.is_finite() {
                return Err(StatesError(format!(
                    "{origin}:{}: x{} = {v} is not finite",
                    ln + 1,
                    i + 1
                )));
            }
            x[i] = f;
        }
        out.push(x);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_states_and_names_the_line_and_column() {
        let x = parse_states("x1, x2\n\n0.5,-1\n1e-3 , 2\n", "s.csv", 2).unwrap();
        assert_eq!(x, vec![vec![0.5, -1.0], vec![1e-3, 2.0]]);
        let e = parse_states("x1,x2\n0.5,abc\n", "s.csv", 2).unwrap_err().0;
        assert!(e.starts_with("s.csv:2: x2 = `abc` is not a number"), "{e}");
        let e = parse_states("x1,x2\n0.5,inf\n", "s.csv", 2).unwrap_err().0;
        assert!(e.contains("s.csv:2: x2 = inf is not finite"), "{e}");
        let e = parse_states("x1\n0.5\n", "s.csv", 2).unwrap_err().0;
        assert!(e.contains("s.csv:1: header must be `x1,x2`"), "{e}");
        let e = parse_states("x1,x2\n0.5\n", "s.csv", 2).unwrap_err().0;
        assert!(e.contains("s.csv:2: expected 2 columns, got 1"), "{e}");
        assert!(parse_states(" \n", "s.csv", 2)
            .unwrap_err()
            .0
            .contains("empty file"));
    }

    #[test]
    fn a_bom_state_names_and_a_long_field() {
        // Excel's UTF-8 byte-order mark; the problem's state names, in any order.
        let names = ["theta".to_string(), "omega".to_string()];
        let x = parse_states_named("\u{feff}x1,x2\n0.5,-1\n", "s.csv", 2, &[]).unwrap();
        assert_eq!(x, vec![vec![0.5, -1.0]]);
        let x = parse_states_named("\u{feff}omega,theta\n0.5,-1\n", "s.csv", 2, &names).unwrap();
        assert_eq!(x, vec![vec![-1.0, 0.5]]);
        let e = parse_states_named("theta,theta\n1,2\n", "s.csv", 2, &names)
            .unwrap_err()
            .0;
        assert!(e.contains("or `theta,omega`"), "{e}");
        // A 100 000-character field is quoted with 80 characters and its length.
        let long = "9".repeat(50_000) + &"z".repeat(50_000);
        let e = parse_states(&format!("x1,x2\n1,{long}\n"), "s.csv", 2)
            .unwrap_err()
            .0;
        assert!(e.len() < 300 && e.contains("(100000 characters)"), "{e}");
    }
}
