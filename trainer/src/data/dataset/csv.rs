//! The dataset's CSV export (module `dataset` doc): one row per record, the kept
//! sequences' columns `u{j}_{k}` last (format 5 only).

use super::Dataset;
use crate::mpc::sensitivity::Degeneracy;

impl Dataset {
    /// The CSV export.
    pub fn to_csv(&self) -> String {
        let (nx, nu) = (self.header.nx as usize, self.header.nu as usize);
        let mut s = String::from("index");
        for i in 1..=nx {
            s += &format!(",x{i}");
        }
        for j in 1..=nu {
            s += &format!(",u{j}");
        }
        for j in 1..=nu {
            for i in 1..=nx {
                s += &format!(",du{j}_dx{i}");
            }
        }
        s += ",cost,status,iterations,kkt,degenerate,max_slack";
        // Kept sequences (version 5): u{j}_{k} for step k, after the older columns.
        let horizon = self.sequence_horizon().unwrap_or(0);
        for k in 0..horizon {
            for j in 1..=nu {
                s += &format!(",u{j}_{k}");
            }
        }
        s += "\n";
        for r in &self.records {
            s += &r.index.to_string();
            for v in r.x.iter().chain(&r.u).chain(&r.du_dx) {
                s += &format!(",{v:?}");
            }
            let deg = match r.degeneracy {
                None => "",
                Some(Degeneracy::WeaklyActive(_)) => "weakly_active",
                Some(Degeneracy::Singular) => "singular",
            };
            s += &format!(
                ",{:?},{},{},{:e},{},{:?}",
                r.cost,
                r.status.as_str(),
                r.iterations,
                r.kkt,
                deg,
                r.max_slack
            );
            for k in 0..horizon * nu {
                s += &format!(",{:?}", r.seq.get(k).copied().unwrap_or(f64::NAN));
            }
            s += "\n";
        }
        s
    }
}
