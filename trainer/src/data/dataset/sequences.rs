//! Format 5's trailer (module `dataset` doc): the kept optimal input sequences
//! u₀*, …, u_{N−1}* of the records ([`Record::seq`](super::Record::seq)), read and checked.

use super::{Dataset, DatasetError};

impl Dataset {
    /// Version [`SEQUENCE_FORMAT_VERSION`]'s trailer: the disagreeing indices and one
    /// sequence per record, all of one length L = N·nu (a multiple of nu) or empty (an
    /// unlabelled state).
    pub(super) fn read_sequences(
        &mut self,
        bytes: &[u8],
        origin: &str,
    ) -> Result<(), DatasetError> {
        let body = crate::io::unseal(bytes).unwrap_or_default();
        let dec = |source| DatasetError::Decode {
            path: origin.to_string(),
            part: "dataset without its sequences",
            source,
        };
        let (_, rest) = postcard::take_from_bytes::<Dataset>(body).map_err(dec)?;
        let (disagree, rest) = postcard::take_from_bytes::<Vec<u64>>(rest).map_err(dec)?;
        let seqs: Vec<Vec<f64>> = postcard::from_bytes(rest).map_err(dec)?;
        let fmt = |reason: String| DatasetError::Format {
            path: origin.to_string(),
            reason,
        };
        if seqs.len() != self.records.len() {
            return Err(fmt(format!(
                "{} sequences for {} records",
                seqs.len(),
                self.records.len()
            )));
        }
        let nu = (self.header.nu as usize).max(1);
        let len = seqs.iter().map(Vec::len).find(|l| *l > 0).unwrap_or(0);
        for (i, s) in seqs.iter().enumerate() {
            if !(s.is_empty() || s.len() == len) || len % nu != 0 {
                return Err(fmt(format!(
                    "record {i}'s sequence has {} values, not N·nu = {len} (nu = {nu})",
                    s.len()
                )));
            }
        }
        for (r, s) in self.records.iter_mut().zip(seqs) {
            r.seq = s;
        }
        self.disagree = disagree;
        Ok(())
    }

    /// The horizon N of the kept sequences (`None`: the dataset keeps none).
    pub fn sequence_horizon(&self) -> Option<usize> {
        let nu = (self.header.nu as usize).max(1);
        self.records
            .iter()
            .map(|r| r.seq.len())
            .find(|l| *l > 0)
            .map(|l| l / nu)
    }
}
