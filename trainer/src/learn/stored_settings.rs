//! How a model file stores its [`TrainSettings`]: the field order of model format 3, with
//! three switches packed into one byte in the place of a postcard `bool`,
//!
//! ```text
//! flags = saturation_aware · 1 + hold_setpoint · 2 + (precision = f32) · 4
//!       + (outputs = sequence) · 8 + (sequence_form = feedback) · 16
//! ```
//! (`sequence_weights` is not stored here: the model's problem file trailer has it.)
//!
//! Contract: a byte 0 or 1 (a plain `bool`, the format-3 files that store only
//! `saturation_aware`) decodes with `hold_setpoint = false` and f64 precision, and settings
//! with those two values encode to that same byte, so such files keep their bytes and
//! their hash. Used by [`TrainedModel`](super::train::TrainedModel)
//! through `#[serde(with)]`; every other encoding of the settings (TOML, JSON) is the
//! derived one.

use crate::problem::{Activation, Outputs, Precision, Schedule, SequenceForm, TrainSettings};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Format 3's layout of the settings; `flags` in place of `saturation_aware`.
#[derive(Serialize, Deserialize)]
struct Stored {
    hidden: Vec<usize>,
    activation: Activation,
    epochs: usize,
    batch_size: usize,
    learning_rate: f64,
    schedule: Schedule,
    lambda: [f64; 3],
    seed: u64,
    target_eps_d: Option<f64>,
    validation_n: usize,
    validation_seed: u64,
    log_every: usize,
    flags: u8,
}

const SATURATION_AWARE: u8 = 1;
const HOLD_SETPOINT: u8 = 2;
const PRECISION_F32: u8 = 4;
const SEQUENCE: u8 = 8;
const FEEDBACK: u8 = 16;

/// Encodes `s` in the stored layout.
pub(super) fn serialize<S: Serializer>(s: &TrainSettings, ser: S) -> Result<S::Ok, S::Error> {
    Stored {
        hidden: s.hidden.clone(),
        activation: s.activation,
        epochs: s.epochs,
        batch_size: s.batch_size,
        learning_rate: s.learning_rate,
        schedule: s.schedule,
        lambda: s.lambda,
        seed: s.seed,
        target_eps_d: s.target_eps_d,
        validation_n: s.validation_n,
        validation_seed: s.validation_seed,
        log_every: s.log_every,
        flags: u8::from(s.saturation_aware) * SATURATION_AWARE
            + u8::from(s.hold_setpoint) * HOLD_SETPOINT
            + u8::from(s.precision == Precision::F32) * PRECISION_F32
            + u8::from(s.outputs == Outputs::Sequence) * SEQUENCE
            + u8::from(s.sequence_form == SequenceForm::Feedback) * FEEDBACK,
    }
    .serialize(ser)
}

/// Decodes the stored layout; unknown flag bits are an error.
pub(super) fn deserialize<'de, D: Deserializer<'de>>(de: D) -> Result<TrainSettings, D::Error> {
    let s = Stored::deserialize(de)?;
    if s.flags & !(SATURATION_AWARE | HOLD_SETPOINT | PRECISION_F32 | SEQUENCE | FEEDBACK) != 0 {
        return Err(serde::de::Error::custom(format!(
            "unknown training flags {:#04x}",
            s.flags
        )));
    }
    Ok(TrainSettings {
        hidden: s.hidden,
        activation: s.activation,
        epochs: s.epochs,
        batch_size: s.batch_size,
        learning_rate: s.learning_rate,
        schedule: s.schedule,
        lambda: s.lambda,
        seed: s.seed,
        target_eps_d: s.target_eps_d,
        validation_n: s.validation_n,
        validation_seed: s.validation_seed,
        log_every: s.log_every,
        saturation_aware: s.flags & SATURATION_AWARE != 0,
        hold_setpoint: s.flags & HOLD_SETPOINT != 0,
        precision: if s.flags & PRECISION_F32 != 0 {
            Precision::F32
        } else {
            Precision::F64
        },
        outputs: if s.flags & SEQUENCE != 0 {
            Outputs::Sequence
        } else {
            Outputs::First
        },
        sequence_weights: None,
        sequence_form: if s.flags & FEEDBACK != 0 {
            SequenceForm::Feedback
        } else {
            SequenceForm::Open
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stored layout of settings without the hold is the derived postcard encoding of
    /// format 3 (a mirror of the settings before `hold_setpoint`), and both switches round
    /// trip.
    #[test]
    fn stored_settings_are_format_3_without_the_hold_and_round_trip() {
        #[derive(Serialize)]
        struct Format3<'a> {
            hidden: &'a [usize],
            activation: Activation,
            epochs: usize,
            batch_size: usize,
            learning_rate: f64,
            schedule: Schedule,
            lambda: [f64; 3],
            seed: u64,
            target_eps_d: Option<f64>,
            validation_n: usize,
            validation_seed: u64,
            log_every: usize,
            saturation_aware: bool,
        }
        #[derive(Serialize, Deserialize, PartialEq, Debug)]
        struct Wrap(#[serde(with = "super")] TrainSettings);
        for (sat, hold) in [(false, false), (true, false), (false, true), (true, true)] {
            let s = TrainSettings {
                saturation_aware: sat,
                hold_setpoint: hold,
                precision: Precision::F64,
                target_eps_d: Some(0.5),
                ..TrainSettings::default()
            };
            let bytes = postcard::to_allocvec(&Wrap(s.clone())).unwrap();
            let back: Wrap = postcard::from_bytes(&bytes).unwrap();
            assert_eq!(back.0, s);
            let old = postcard::to_allocvec(&Format3 {
                hidden: &s.hidden,
                activation: s.activation,
                epochs: s.epochs,
                batch_size: s.batch_size,
                learning_rate: s.learning_rate,
                schedule: s.schedule,
                lambda: s.lambda,
                seed: s.seed,
                target_eps_d: s.target_eps_d,
                validation_n: s.validation_n,
                validation_seed: s.validation_seed,
                log_every: s.log_every,
                saturation_aware: s.saturation_aware,
            })
            .unwrap();
            assert_eq!(bytes == old, !hold, "sat {sat} hold {hold}");
        }
        // The f32 engine round trips (flag 4); an unknown bit is an error.
        let f32s = TrainSettings::default();
        assert_eq!(f32s.precision, Precision::F32);
        let bytes = postcard::to_allocvec(&Wrap(f32s.clone())).unwrap();
        assert_eq!(postcard::from_bytes::<Wrap>(&bytes).unwrap().0, f32s);
        // A sequence net round trips (flag 8; its per-step weights live in the problem file).
        let seq = TrainSettings {
            outputs: Outputs::Sequence,
            ..TrainSettings::default()
        };
        let bytes = postcard::to_allocvec(&Wrap(seq.clone())).unwrap();
        assert_eq!(*bytes.last().unwrap(), 8 | 4 | 2);
        assert_eq!(postcard::from_bytes::<Wrap>(&bytes).unwrap().0, seq);
        // The feedback form round trips (flag 16); an old sequence net (no flag) is open.
        let fb = TrainSettings {
            outputs: Outputs::Sequence,
            sequence_form: SequenceForm::Feedback,
            ..TrainSettings::default()
        };
        let bytes = postcard::to_allocvec(&Wrap(fb.clone())).unwrap();
        assert_eq!(*bytes.last().unwrap(), 16 | 8 | 4 | 2);
        assert_eq!(postcard::from_bytes::<Wrap>(&bytes).unwrap().0, fb);
        let mut bad = postcard::to_allocvec(&Wrap(TrainSettings::default())).unwrap();
        *bad.last_mut().unwrap() = 32;
        assert!(postcard::from_bytes::<Wrap>(&bad).is_err());
    }
}
