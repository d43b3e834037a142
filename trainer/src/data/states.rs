//! The states CSV that `trainer solve` and `trainer eval` read: a header `x1,…,xn`, then one
//! finite state x ∈ ℝⁿ per row (blank lines skipped). [`parse_states`] owns the format; every
//! error names the file, the line and (for a bad number) the column.

/// A states CSV that cannot be read; the message names the file, line and column at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct StatesError(pub String);

/// Parses the states CSV `text` (from `origin`) for a problem with `nx` states.
pub fn parse_states(text: &str, origin: &str, nx: usize) -> Result<Vec<Vec<f64>>, StatesError> {
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
    if cols != expected {
        return Err(StatesError(format!(
            "{origin}:1: header must be `{}` for this problem ({nx} states), got `{}`",
            expected.join(","),
            header.trim()
        )));
    }
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
        let mut x = Vec::with_capacity(nx);
        for (i, v) in vals.iter().enumerate() {
            let f: f64 = v.parse().map_err(|e| {
                StatesError(format!(
                    "{origin}:{}: x{} = `{v}` is not a number: {e}",
                    ln + 1,
                    i + 1
                ))
            })?;
            if !f.is_finite() {
                return Err(StatesError(format!(
                    "{origin}:{}: x{} = {v} is not finite",
                    ln + 1,
                    i + 1
                )));
            }
            x.push(f);
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
}
