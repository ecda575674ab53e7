//! A match's state as bytes, and back: what lets a server that stopped bring a match back at
//! its last checkpoint instead of replaying it from the first tick.
//!
//! A checkpoint holds only what changes while a match plays (poses, particle clouds, random
//! streams' positions, plans, radio traffic, the event log). What a match derives from its
//! map and settings (view tables, likelihood fields, histograms' grids) is not saved: a
//! fresh `World::new` on the same map and settings builds it, and [`Restore`] puts the
//! saved parts back into that fresh world. Those derivations are deterministic, so the
//! result is the match that was saved, bit for bit.
//!
//! Completeness is checked by the compiler: the macros destructure every struct without
//! `..`, so a field added to a saved type that is not listed as saved or derived is a build
//! error, not a match that silently drifts after a restore. Each saved struct also writes a
//! tag of its type and field names, so a checkpoint written by a build whose types differ
//! is refused (the caller then replays from the start) rather than misread.
//!
//! The encoding is hand-written rather than serde's: the core's floor keeps serde out
//! (`tests/tidy.rs`), and the format is private to one build's restore, never an interface.

use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::{Matrix3, Point2, Vector2};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The first bytes of every checkpoint, and its format's version.
const MAGIC: &[u8; 8] = b"LTCKPT01";

/// Why a checkpoint could not be restored.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CheckpointError {
    #[error("not a checkpoint of this format")]
    NotACheckpoint,
    #[error("it ends in the middle of {0}")]
    Truncated(&'static str),
    #[error("{0} was written by a build whose types differ")]
    OtherBuild(&'static str),
    #[error("{what} does not match the match it restores into")]
    Mismatch { what: &'static str },
    #[error("a bad value for {0}")]
    BadValue(&'static str),
    #[error("{0} bytes are left over after the whole state")]
    Trailing(usize),
}

/// Bytes being written, little-endian.
#[derive(Debug, Default)]
pub struct Writer {
    bytes: Vec<u8>,
}

impl Writer {
    pub fn new() -> Writer {
        let mut w = Writer::default();
        w.bytes.extend_from_slice(MAGIC);
        w
    }

    pub fn put(&mut self, bytes: &[u8]) {
        self.bytes.extend_from_slice(bytes);
    }

    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }
}

/// Bytes being read back.
#[derive(Debug)]
pub struct Reader<'a> {
    bytes: &'a [u8],
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8]) -> Result<Reader<'a>, CheckpointError> {
        match bytes.strip_prefix(MAGIC.as_slice()) {
            Some(rest) => Ok(Reader { bytes: rest }),
            None => Err(CheckpointError::NotACheckpoint),
        }
    }

    pub fn take<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], CheckpointError> {
        let (head, rest) = self
            .bytes
            .split_first_chunk::<N>()
            .ok_or(CheckpointError::Truncated(what))?;
        self.bytes = rest;
        Ok(*head)
    }

    /// A length written by [`Writer`]: at most the bytes left (every element takes one at
    /// least), so a damaged length cannot make the reader allocate more than it was given.
    pub fn len(&mut self, what: &'static str) -> Result<usize, CheckpointError> {
        let n = u32::from_le_bytes(self.take(what)?) as usize;
        if n > self.bytes.len() {
            return Err(CheckpointError::Truncated(what));
        }
        Ok(n)
    }

    /// Checks the tag of a saved struct (see [`schema_tag`]).
    pub fn expect_tag(&mut self, tag: u32, what: &'static str) -> Result<(), CheckpointError> {
        if u32::from_le_bytes(self.take(what)?) == tag {
            Ok(())
        } else {
            Err(CheckpointError::OtherBuild(what))
        }
    }

    /// Fails unless every byte was read.
    pub fn finish(self) -> Result<(), CheckpointError> {
        match self.bytes.len() {
            0 => Ok(()),
            n => Err(CheckpointError::Trailing(n)),
        }
    }
}

/// FNV-1a of a struct's name and fields as the macros spell them: the same in every build
/// whose type has the same fields in the same order.
pub const fn schema_tag(schema: &str) -> u32 {
    let bytes = schema.as_bytes();
    let mut h: u32 = 0x811c_9dc5;
    let mut i = 0;
    while i < bytes.len() {
        h ^= bytes[i] as u32;
        h = h.wrapping_mul(0x0100_0193);
        i += 1;
    }
    h
}

/// A value saved whole and loaded whole.
pub trait Plain: Sized {
    fn save(&self, w: &mut Writer);
    fn load(r: &mut Reader) -> Result<Self, CheckpointError>;
}

/// A value part of which is derived from the map and settings: the saved parts go back into
/// a freshly built one.
pub trait Restore {
    fn save(&self, w: &mut Writer);
    fn restore(&mut self, r: &mut Reader) -> Result<(), CheckpointError>;
}

/// `Plain` for a struct, every field saved: `plain_struct!(Pose { pos, theta })`.
macro_rules! plain_struct {
    ($ty:ident { $($field:ident),* $(,)? }) => {
        impl $crate::checkpoint::Plain for $ty {
            fn save(&self, w: &mut $crate::checkpoint::Writer) {
                const TAG: u32 =
                    $crate::checkpoint::schema_tag(stringify!($ty { $($field),* }));
                $crate::checkpoint::Plain::save(&TAG, w);
                let $ty { $($field),* } = self;
                $( $crate::checkpoint::Plain::save($field, w); )*
            }
            fn load(
                r: &mut $crate::checkpoint::Reader,
            ) -> Result<Self, $crate::checkpoint::CheckpointError> {
                const TAG: u32 =
                    $crate::checkpoint::schema_tag(stringify!($ty { $($field),* }));
                r.expect_tag(TAG, stringify!($ty))?;
                Ok($ty { $($field: $crate::checkpoint::Plain::load(r)?),* })
            }
        }
    };
}
pub(crate) use plain_struct;

/// `Restore` for a struct: `plain` fields are saved and loaded whole, `nested` ones restored
/// in place, `derived` ones (built from the map and settings) left as the fresh value has
/// them. Every field must be named in one of the three.
macro_rules! restore_struct {
    ($ty:ident {
        plain: [$($plain:ident),* $(,)?],
        nested: [$($nested:ident),* $(,)?],
        derived: [$($derived:ident),* $(,)?] $(,)?
    }) => {
        impl $crate::checkpoint::Restore for $ty {
            fn save(&self, w: &mut $crate::checkpoint::Writer) {
                const TAG: u32 = $crate::checkpoint::schema_tag(stringify!(
                    $ty { $($plain),* ; $($nested),* ; $($derived),* }
                ));
                $crate::checkpoint::Plain::save(&TAG, w);
                let $ty { $($plain,)* $($nested,)* $($derived: _,)* } = self;
                $( $crate::checkpoint::Plain::save($plain, w); )*
                $( $crate::checkpoint::Restore::save($nested, w); )*
            }
            fn restore(
                &mut self,
                r: &mut $crate::checkpoint::Reader,
            ) -> Result<(), $crate::checkpoint::CheckpointError> {
                const TAG: u32 = $crate::checkpoint::schema_tag(stringify!(
                    $ty { $($plain),* ; $($nested),* ; $($derived),* }
                ));
                r.expect_tag(TAG, stringify!($ty))?;
                let $ty { $($plain,)* $($nested,)* $($derived: _,)* } = self;
                $( *$plain = $crate::checkpoint::Plain::load(r)?; )*
                $( $crate::checkpoint::Restore::restore($nested, r)?; )*
                Ok(())
            }
        }
    };
}
pub(crate) use restore_struct;

macro_rules! plain_number {
    ($($ty:ty),*) => {$(
        impl Plain for $ty {
            fn save(&self, w: &mut Writer) {
                w.put(&self.to_le_bytes());
            }
            fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
                Ok(<$ty>::from_le_bytes(r.take(stringify!($ty))?))
            }
        }
    )*};
}
plain_number!(u8, u16, u32, u64, u128, i32, i64, f32, f64);

impl Plain for usize {
    fn save(&self, w: &mut Writer) {
        (*self as u64).save(w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        usize::try_from(u64::load(r)?).map_err(|_| CheckpointError::BadValue("usize"))
    }
}

impl Plain for bool {
    fn save(&self, w: &mut Writer) {
        (*self as u8).save(w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        match u8::load(r)? {
            0 => Ok(false),
            1 => Ok(true),
            _ => Err(CheckpointError::BadValue("bool")),
        }
    }
}

impl Plain for String {
    fn save(&self, w: &mut Writer) {
        (self.len() as u32).save(w);
        w.put(self.as_bytes());
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        let n = r.len("a string")?;
        let (head, rest) = r.bytes.split_at(n);
        r.bytes = rest;
        String::from_utf8(head.to_vec()).map_err(|_| CheckpointError::BadValue("a string"))
    }
}

impl<T: Plain> Plain for Option<T> {
    fn save(&self, w: &mut Writer) {
        match self {
            None => false.save(w),
            Some(v) => {
                true.save(w);
                v.save(w);
            }
        }
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        Ok(match bool::load(r)? {
            false => None,
            true => Some(T::load(r)?),
        })
    }
}

fn save_all<'a, T: Plain + 'a>(items: impl ExactSizeIterator<Item = &'a T>, w: &mut Writer) {
    (items.len() as u32).save(w);
    items.for_each(|v| v.save(w));
}

impl<T: Plain> Plain for Vec<T> {
    fn save(&self, w: &mut Writer) {
        save_all(self.iter(), w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        let n = r.len("a list")?;
        (0..n).map(|_| T::load(r)).collect()
    }
}

impl<T: Plain> Plain for VecDeque<T> {
    fn save(&self, w: &mut Writer) {
        save_all(self.iter(), w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        let n = r.len("a queue")?;
        (0..n).map(|_| T::load(r)).collect()
    }
}

impl<T: Plain> Plain for Box<T> {
    fn save(&self, w: &mut Writer) {
        (**self).save(w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        T::load(r).map(Box::new)
    }
}

/// Shared values come back unshared: nothing in the core compares pointers.
impl<T: Plain> Plain for Arc<T> {
    fn save(&self, w: &mut Writer) {
        (**self).save(w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        T::load(r).map(Arc::new)
    }
}

impl<A: Plain, B: Plain> Plain for (A, B) {
    fn save(&self, w: &mut Writer) {
        self.0.save(w);
        self.1.save(w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        Ok((A::load(r)?, B::load(r)?))
    }
}

impl<A: Plain, B: Plain, C: Plain> Plain for (A, B, C) {
    fn save(&self, w: &mut Writer) {
        self.0.save(w);
        self.1.save(w);
        self.2.save(w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        Ok((A::load(r)?, B::load(r)?, C::load(r)?))
    }
}

impl Plain for Point2<f32> {
    fn save(&self, w: &mut Writer) {
        self.x.save(w);
        self.y.save(w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        Ok(Point2::new(f32::load(r)?, f32::load(r)?))
    }
}

impl Plain for Vector2<f32> {
    fn save(&self, w: &mut Writer) {
        self.x.save(w);
        self.y.save(w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        Ok(Vector2::new(f32::load(r)?, f32::load(r)?))
    }
}

impl Plain for Matrix3<f32> {
    fn save(&self, w: &mut Writer) {
        self.iter().for_each(|v| v.save(w));
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        let mut m = Matrix3::zeros();
        for v in m.iter_mut() {
            *v = f32::load(r)?;
        }
        Ok(m)
    }
}

/// A random stream as its seed, stream number and position in it: restored, it draws what
/// the saved one would have drawn next.
impl Plain for ChaCha8Rng {
    fn save(&self, w: &mut Writer) {
        w.put(&self.get_seed());
        self.get_stream().save(w);
        self.get_word_pos().save(w);
    }
    fn load(r: &mut Reader) -> Result<Self, CheckpointError> {
        let mut rng = ChaCha8Rng::from_seed(r.take::<32>("a random stream")?);
        rng.set_stream(u64::load(r)?);
        rng.set_word_pos(u128::load(r)?);
        Ok(rng)
    }
}

impl<T: Restore> Restore for Vec<T> {
    fn save(&self, w: &mut Writer) {
        (self.len() as u32).save(w);
        self.iter().for_each(|v| v.save(w));
    }
    fn restore(&mut self, r: &mut Reader) -> Result<(), CheckpointError> {
        if r.len("a list")? != self.len() {
            return Err(CheckpointError::Mismatch {
                what: "a list's length",
            });
        }
        self.iter_mut().try_for_each(|v| v.restore(r))
    }
}

impl<T: Restore> Restore for Option<T> {
    fn save(&self, w: &mut Writer) {
        self.is_some().save(w);
        if let Some(v) = self {
            v.save(w);
        }
    }
    fn restore(&mut self, r: &mut Reader) -> Result<(), CheckpointError> {
        match (bool::load(r)?, self) {
            (false, None) => Ok(()),
            (true, Some(v)) => v.restore(r),
            _ => Err(CheckpointError::Mismatch {
                what: "an optional part",
            }),
        }
    }
}

impl<T: Restore> Restore for Box<T> {
    fn save(&self, w: &mut Writer) {
        (**self).save(w);
    }
    fn restore(&mut self, r: &mut Reader) -> Result<(), CheckpointError> {
        (**self).restore(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, RngExt};

    fn round_trip<T: Plain>(v: &T) -> T {
        let mut w = Writer::new();
        v.save(&mut w);
        let bytes = w.into_bytes();
        let mut r = Reader::new(&bytes).unwrap();
        let back = T::load(&mut r).unwrap();
        r.finish().unwrap();
        back
    }

    #[test]
    fn a_restored_random_stream_draws_what_the_saved_one_would_have() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        rng.set_stream(3);
        for _ in 0..37 {
            let _: u32 = rng.next_u32();
        }
        let mut back = round_trip(&rng);
        let a: Vec<f64> = (0..100).map(|_| rng.random()).collect();
        let b: Vec<f64> = (0..100).map(|_| back.random()).collect();
        assert_eq!(a, b);
    }

    #[test]
    fn values_come_back_as_they_were() {
        let v: (Vec<Option<String>>, VecDeque<(u64, f32)>, bool) = (
            vec![Some("ä".into()), None],
            VecDeque::from([(1, -0.5), (u64::MAX, f32::NAN)]),
            true,
        );
        let back = round_trip(&v);
        assert_eq!(back.0, v.0);
        assert_eq!(back.1[0], v.1[0]);
        assert!(back.1[1].1.is_nan());
        assert!(back.2);
    }

    #[test]
    fn damaged_bytes_are_refused_not_misread() {
        assert_eq!(
            Reader::new(b"nonsense").unwrap_err(),
            CheckpointError::NotACheckpoint
        );
        let mut w = Writer::new();
        vec![1u64, 2, 3].save(&mut w);
        let bytes = w.into_bytes();
        let mut short = Reader::new(&bytes[..bytes.len() - 1]).unwrap();
        assert!(matches!(
            Vec::<u64>::load(&mut short),
            Err(CheckpointError::Truncated(_))
        ));
        // A length far beyond the bytes allocates nothing.
        let mut huge = Writer::new();
        u32::MAX.save(&mut huge);
        let bytes = huge.into_bytes();
        let mut r = Reader::new(&bytes).unwrap();
        assert!(Vec::<u8>::load(&mut r).is_err());
    }
}
