//! The protobuf wire format of the few ONNX messages this project reads and writes.
//!
//! A message is a sequence of fields `key = (number << 3) | wire_type` followed by a varint
//! (type 0), 8 bytes (type 1), a length-prefixed byte string (type 2: strings, bytes,
//! sub-messages, packed repeated scalars) or 4 bytes (type 5). [`Writer`] encodes fields,
//! [`fields`] decodes one message level into `(number, Value)` pairs; the typed messages
//! (`ModelProto`, `GraphProto`, `NodeProto`, `TensorProto`, …) are assembled in `write`
//! and taken apart in `read` with the field numbers of `onnx.proto` (ONNX 1.x, listed
//! there). Hand-written on purpose: eight messages and two dozen fields do not justify a
//! code generator (`prost-build` needs `protoc`) or a generated-code crate.

/// One decoded field value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value<'a> {
    /// Wire type 0.
    Varint(u64),
    /// Wire type 1 (little-endian 8 bytes).
    Fixed64(u64),
    /// Wire type 2.
    Bytes(&'a [u8]),
    /// Wire type 5 (little-endian 4 bytes).
    Fixed32(u32),
}

/// A malformed protobuf byte string (the offset of the fault).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("malformed protobuf at byte {offset}: {reason}")]
pub struct WireError {
    /// Offset in the message being decoded.
    pub offset: usize,
    /// What is wrong.
    pub reason: &'static str,
}

fn varint(b: &[u8], pos: &mut usize) -> Result<u64, WireError> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let Some(&byte) = b.get(*pos) else {
            return Err(WireError {
                offset: *pos,
                reason: "truncated varint",
            });
        };
        *pos += 1;
        v |= u64::from(byte & 0x7f) << shift;
        if byte & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(WireError {
        offset: *pos,
        reason: "varint longer than 10 bytes",
    })
}

fn take<'a>(b: &'a [u8], pos: &mut usize, n: usize) -> Result<&'a [u8], WireError> {
    let end = pos
        .checked_add(n)
        .filter(|&e| e <= b.len())
        .ok_or(WireError {
            offset: *pos,
            reason: "field runs past the end",
        })?;
    let s = &b[*pos..end];
    *pos = end;
    Ok(s)
}

/// The fields of one message, in order.
pub fn fields(b: &[u8]) -> Result<Vec<(u32, Value<'_>)>, WireError> {
    let mut out = Vec::new();
    let mut pos = 0;
    while pos < b.len() {
        let at = pos;
        let key = varint(b, &mut pos)?;
        let number = u32::try_from(key >> 3).map_err(|_| WireError {
            offset: at,
            reason: "field number too large",
        })?;
        if number == 0 {
            return Err(WireError {
                offset: at,
                reason: "field number 0",
            });
        }
        let v = match key & 7 {
            0 => Value::Varint(varint(b, &mut pos)?),
            1 => Value::Fixed64(u64::from_le_bytes(
                take(b, &mut pos, 8)?.try_into().expect("8 bytes"),
            )),
            2 => {
                let n = varint(b, &mut pos)?;
                let n = usize::try_from(n).map_err(|_| WireError {
                    offset: at,
                    reason: "length too large",
                })?;
                Value::Bytes(take(b, &mut pos, n)?)
            }
            5 => Value::Fixed32(u32::from_le_bytes(
                take(b, &mut pos, 4)?.try_into().expect("4 bytes"),
            )),
            _ => {
                return Err(WireError {
                    offset: at,
                    reason: "unsupported wire type (groups are not used by ONNX)",
                })
            }
        };
        out.push((number, v));
    }
    Ok(out)
}

/// The varints of a repeated integer field: packed (one byte string) or one per field.
pub fn ints(v: &Value<'_>) -> Result<Vec<i64>, WireError> {
    match v {
        Value::Varint(x) => Ok(vec![*x as i64]),
        Value::Bytes(b) => {
            let mut pos = 0;
            let mut out = Vec::new();
            while pos < b.len() {
                out.push(varint(b, &mut pos)? as i64);
            }
            Ok(out)
        }
        _ => Err(WireError {
            offset: 0,
            reason: "integer field with a fixed-width wire type",
        }),
    }
}

/// The values of a repeated `float` field: packed or one per field.
pub fn floats(v: &Value<'_>) -> Result<Vec<f32>, WireError> {
    match v {
        Value::Fixed32(x) => Ok(vec![f32::from_bits(*x)]),
        Value::Bytes(b) if b.len() % 4 == 0 => Ok(b
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect()),
        _ => Err(WireError {
            offset: 0,
            reason: "float field of the wrong wire type or length",
        }),
    }
}

/// The values of a repeated `double` field: packed or one per field.
pub fn doubles(v: &Value<'_>) -> Result<Vec<f64>, WireError> {
    match v {
        Value::Fixed64(x) => Ok(vec![f64::from_bits(*x)]),
        Value::Bytes(b) if b.len() % 8 == 0 => Ok(b
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect()),
        _ => Err(WireError {
            offset: 0,
            reason: "double field of the wrong wire type or length",
        }),
    }
}

/// A string field (UTF-8; invalid bytes replaced).
pub fn string(v: &Value<'_>) -> String {
    match v {
        Value::Bytes(b) => String::from_utf8_lossy(b).into_owned(),
        _ => String::new(),
    }
}

/// An encoder of one message.
#[derive(Debug, Default, Clone)]
pub struct Writer {
    /// The encoded bytes so far.
    pub buf: Vec<u8>,
}

impl Writer {
    fn raw_varint(&mut self, mut v: u64) {
        while v >= 0x80 {
            self.buf.push((v as u8) | 0x80);
            v >>= 7;
        }
        self.buf.push(v as u8);
    }
    fn key(&mut self, number: u32, wire: u8) {
        self.raw_varint((u64::from(number) << 3) | u64::from(wire));
    }
    /// An integer field (int32/int64/enum; negative values as 10-byte varints).
    pub fn int(&mut self, number: u32, v: i64) -> &mut Self {
        self.key(number, 0);
        self.raw_varint(v as u64);
        self
    }
    /// A byte-string field.
    pub fn bytes(&mut self, number: u32, v: &[u8]) -> &mut Self {
        self.key(number, 2);
        self.raw_varint(v.len() as u64);
        self.buf.extend_from_slice(v);
        self
    }
    /// A string field.
    pub fn string(&mut self, number: u32, v: &str) -> &mut Self {
        self.bytes(number, v.as_bytes())
    }
    /// A sub-message field.
    pub fn message(&mut self, number: u32, m: &Writer) -> &mut Self {
        self.bytes(number, &m.buf)
    }
    /// A `float` field (wire type 5).
    pub fn float(&mut self, number: u32, v: f32) -> &mut Self {
        self.key(number, 5);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }
    /// A packed repeated integer field.
    pub fn packed_ints(&mut self, number: u32, v: &[i64]) -> &mut Self {
        let mut w = Writer::default();
        for x in v {
            w.raw_varint(*x as u64);
        }
        self.bytes(number, &w.buf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_round_trip_through_the_writer() {
        let mut inner = Writer::default();
        inner.string(1, "tanh").int(2, -3);
        let mut w = Writer::default();
        w.int(1, 300)
            .message(7, &inner)
            .float(2, 1.5)
            .packed_ints(8, &[1, 1 << 40, -1]);
        let f = fields(&w.buf).unwrap();
        assert_eq!(f[0], (1, Value::Varint(300)));
        assert_eq!(f[2], (2, Value::Fixed32(1.5f32.to_bits())));
        assert_eq!(ints(&f[3].1).unwrap(), vec![1, 1 << 40, -1]);
        let Value::Bytes(b) = f[1].1 else {
            panic!("not bytes")
        };
        let g = fields(b).unwrap();
        assert_eq!(string(&g[0].1), "tanh");
        assert_eq!(ints(&g[1].1).unwrap(), vec![-3]);
    }

    #[test]
    fn truncated_input_is_an_error_with_its_offset() {
        let mut w = Writer::default();
        w.string(3, "abcdef");
        let cut = &w.buf[..w.buf.len() - 2];
        let e = fields(cut).unwrap_err();
        assert_eq!(e.reason, "field runs past the end");
        assert!(fields(&[0x08, 0x80]).is_err());
        assert!(fields(&[0x0b]).is_err(), "wire type 3 (group) refused");
    }

    #[test]
    fn repeated_scalars_decode_packed_and_unpacked() {
        let v: Vec<u8> = [1.0f32, -2.5]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        assert_eq!(floats(&Value::Bytes(&v)).unwrap(), vec![1.0, -2.5]);
        assert_eq!(
            doubles(&Value::Fixed64(0.1f64.to_bits())).unwrap(),
            vec![0.1]
        );
        assert!(floats(&Value::Bytes(&v[..5])).is_err());
    }
}
