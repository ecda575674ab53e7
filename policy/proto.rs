//! The protocol buffers wire format, as far as ONNX's messages need it: a message is a run of
//! fields, each a key (field number and wire type, a varint) and a value. Only reading, of a
//! byte slice held in memory; every length is checked against what is left, so a malformed or
//! hostile model is an error, never a panic or an allocation larger than the input.
//!
//! Why not `prost`: it generates its types from `.proto` files at build time with `protoc`, a
//! C++ tool the build would need; the five ONNX messages read here are a page of code.

use crate::PolicyError;

/// A field's value as the wire carries it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value<'a> {
    Varint(u64),
    Fixed64(u64),
    Bytes(&'a [u8]),
    Fixed32(u32),
}

impl<'a> Value<'a> {
    pub fn bytes(self, what: &'static str) -> Result<&'a [u8], PolicyError> {
        match self {
            Value::Bytes(b) => Ok(b),
            _ => Err(PolicyError::Malformed(what)),
        }
    }

    pub fn varint(self, what: &'static str) -> Result<u64, PolicyError> {
        match self {
            Value::Varint(v) => Ok(v),
            _ => Err(PolicyError::Malformed(what)),
        }
    }

    pub fn string(self, what: &'static str) -> Result<&'a str, PolicyError> {
        std::str::from_utf8(self.bytes(what)?).map_err(|_| PolicyError::Malformed(what))
    }
}

/// The fields of one message, in order.
pub struct Fields<'a> {
    rest: &'a [u8],
}

impl<'a> Fields<'a> {
    pub fn new(message: &'a [u8]) -> Fields<'a> {
        Fields { rest: message }
    }
}

fn varint(rest: &mut &[u8]) -> Result<u64, PolicyError> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let (&b, tail) = rest
            .split_first()
            .ok_or(PolicyError::Malformed("a varint runs past the end"))?;
        *rest = tail;
        v |= u64::from(b & 0x7f) << shift;
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(PolicyError::Malformed("a varint longer than 10 bytes"))
}

fn take<'a>(rest: &mut &'a [u8], n: u64) -> Result<&'a [u8], PolicyError> {
    let n = usize::try_from(n).map_err(|_| PolicyError::Malformed("a length past the end"))?;
    if n > rest.len() {
        return Err(PolicyError::Malformed("a length past the end"));
    }
    let (head, tail) = rest.split_at(n);
    *rest = tail;
    Ok(head)
}

impl<'a> Iterator for Fields<'a> {
    type Item = Result<(u32, Value<'a>), PolicyError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.rest.is_empty() {
            return None;
        }
        let field = (|| {
            let key = varint(&mut self.rest)?;
            let number = u32::try_from(key >> 3).map_err(|_| PolicyError::Malformed("a key"))?;
            let value = match key & 7 {
                0 => Value::Varint(varint(&mut self.rest)?),
                1 => {
                    let b = take(&mut self.rest, 8)?;
                    Value::Fixed64(u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
                }
                2 => {
                    let n = varint(&mut self.rest)?;
                    Value::Bytes(take(&mut self.rest, n)?)
                }
                5 => {
                    let b = take(&mut self.rest, 4)?;
                    Value::Fixed32(u32::from_le_bytes(b.try_into().unwrap_or([0; 4])))
                }
                _ => {
                    return Err(PolicyError::Malformed(
                        "a wire type this reader does not know",
                    ));
                }
            };
            Ok((number, value))
        })();
        if field.is_err() {
            // Nothing after a malformed field can be read.
            self.rest = &[];
        }
        Some(field)
    }
}

/// The integers of a repeated `int64` field's value: packed (one run of varints) or one.
pub fn int64s(value: Value, out: &mut Vec<i64>, what: &'static str) -> Result<(), PolicyError> {
    match value {
        Value::Varint(v) => out.push(v as i64),
        Value::Bytes(mut b) => {
            while !b.is_empty() {
                out.push(varint(&mut b)? as i64);
            }
        }
        _ => return Err(PolicyError::Malformed(what)),
    }
    Ok(())
}

/// The floats of a repeated `float` field's value: packed (little-endian, 4 bytes each) or
/// one, appended to `out` while it holds at most `limit`.
pub fn floats(
    value: Value,
    out: &mut Vec<f32>,
    limit: usize,
    what: &'static str,
) -> Result<(), PolicyError> {
    match value {
        Value::Fixed32(v) => out.push(f32::from_bits(v)),
        Value::Bytes(b) => {
            if b.len() % 4 != 0 {
                return Err(PolicyError::Malformed(what));
            }
            if out.len() + b.len() / 4 > limit {
                return Err(PolicyError::TooLarge(what));
            }
            out.extend(
                b.chunks_exact(4)
                    .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            );
        }
        _ => return Err(PolicyError::Malformed(what)),
    }
    if out.len() > limit {
        return Err(PolicyError::TooLarge(what));
    }
    Ok(())
}

pub mod write {
    //! The other way: messages built field by field (`crate::testing`'s models).

    pub fn varint(out: &mut Vec<u8>, mut v: u64) {
        loop {
            let b = (v & 0x7f) as u8;
            v >>= 7;
            if v == 0 {
                out.push(b);
                return;
            }
            out.push(b | 0x80);
        }
    }

    pub fn key(out: &mut Vec<u8>, field: u32, wire: u8) {
        varint(out, u64::from(field) << 3 | u64::from(wire));
    }

    pub fn bytes(out: &mut Vec<u8>, field: u32, b: &[u8]) {
        key(out, field, 2);
        varint(out, b.len() as u64);
        out.extend_from_slice(b);
    }

    pub fn int(out: &mut Vec<u8>, field: u32, v: i64) {
        key(out, field, 0);
        varint(out, v as u64);
    }

    #[cfg(test)]
    pub fn float(out: &mut Vec<u8>, field: u32, v: f32) {
        key(out, field, 5);
        out.extend_from_slice(&v.to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_read_back_as_written() {
        let mut m = Vec::new();
        write::int(&mut m, 1, 300);
        write::bytes(&mut m, 2, b"abc");
        write::float(&mut m, 3, 1.5);
        let got: Vec<_> = Fields::new(&m).collect::<Result<_, _>>().unwrap();
        assert_eq!(
            got,
            [
                (1, Value::Varint(300)),
                (2, Value::Bytes(b"abc")),
                (3, Value::Fixed32(1.5f32.to_bits()))
            ]
        );
    }

    #[test]
    fn a_length_past_the_end_is_an_error() {
        let mut m = Vec::new();
        write::key(&mut m, 2, 2);
        write::varint(&mut m, 1 << 40);
        let first = Fields::new(&m).next().unwrap();
        assert!(matches!(first, Err(PolicyError::Malformed(_))));
        assert!(Fields::new(&[0xff; 11]).next().unwrap().is_err());
    }
}
