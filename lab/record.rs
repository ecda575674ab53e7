//! What one run of an experiment measured, as one line of text in a part file and back,
//! without losing a bit: the merge must aggregate exactly the numbers a single run would.
//!
//! Fields are separated by spaces. Floating-point numbers are written by their `Debug`
//! form, the shortest decimal that reads back as the same value (`0.1`, `1e-7`, `NaN`,
//! `-0.0`), so a number survives the trip bit for bit and the file stays readable; the tests
//! hold that to random bit patterns. A list is its length, then its items.

use nalgebra::Point2;

/// A run's measurements, or a part of them, written as fields of a line.
pub trait Record: Sized {
    fn write(&self, out: &mut Line);
    fn read(input: &mut Fields) -> Result<Self, String>;
}

/// A line being written: fields separated by single spaces.
#[derive(Debug, Default)]
pub struct Line(String);

impl Line {
    pub fn field(&mut self, text: impl std::fmt::Display) {
        if !self.0.is_empty() {
            self.0.push(' ');
        }
        self.0.push_str(&text.to_string());
    }

    pub fn into_string(self) -> String {
        self.0
    }
}

/// A line being read, field by field.
pub struct Fields<'a> {
    rest: std::str::SplitAsciiWhitespace<'a>,
    read: usize,
}

impl<'a> Fields<'a> {
    pub fn new(line: &'a str) -> Fields<'a> {
        Fields {
            rest: line.split_ascii_whitespace(),
            read: 0,
        }
    }

    /// The next field, parsed as `T` (`what` names it in the error).
    pub fn next<T: std::str::FromStr>(&mut self, what: &str) -> Result<T, String> {
        self.read += 1;
        let n = self.read;
        let text = self
            .rest
            .next()
            .ok_or_else(|| format!("field {n} ({what}) is missing"))?;
        text.parse()
            .map_err(|_| format!("field {n} ({what}): {text:?} is not {what}"))
    }

    /// Checks that nothing is left on the line.
    pub fn end(mut self) -> Result<(), String> {
        match self.rest.next() {
            None => Ok(()),
            Some(extra) => Err(format!(
                "{extra:?} after the {} fields a run has",
                self.read
            )),
        }
    }
}

/// Writes `r` as one line.
pub fn to_line(r: &impl Record) -> String {
    let mut line = Line::default();
    r.write(&mut line);
    line.into_string()
}

/// Reads one line that holds exactly one `R`.
pub fn from_line<R: Record>(line: &str) -> Result<R, String> {
    let mut fields = Fields::new(line);
    let r = R::read(&mut fields)?;
    fields.end()?;
    Ok(r)
}

impl Record for f64 {
    fn write(&self, out: &mut Line) {
        out.field(format_args!("{self:?}"));
    }
    fn read(input: &mut Fields) -> Result<f64, String> {
        input.next("a number")
    }
}

impl Record for f32 {
    fn write(&self, out: &mut Line) {
        out.field(format_args!("{self:?}"));
    }
    fn read(input: &mut Fields) -> Result<f32, String> {
        input.next("a number")
    }
}

impl Record for u32 {
    fn write(&self, out: &mut Line) {
        out.field(self);
    }
    fn read(input: &mut Fields) -> Result<u32, String> {
        input.next("a count")
    }
}

/// A number, or `-` for none (a run that captured nothing, found nothing).
impl Record for Option<f64> {
    fn write(&self, out: &mut Line) {
        match self {
            Some(x) => x.write(out),
            None => out.field("-"),
        }
    }
    fn read(input: &mut Fields) -> Result<Option<f64>, String> {
        let text: String = input.next("a number or -")?;
        if text == "-" {
            return Ok(None);
        }
        text.parse()
            .map(Some)
            .map_err(|_| format!("{text:?} is not a number or -"))
    }
}

impl<T: Record> Record for Vec<T> {
    fn write(&self, out: &mut Line) {
        out.field(self.len());
        self.iter().for_each(|x| x.write(out));
    }
    fn read(input: &mut Fields) -> Result<Vec<T>, String> {
        let n: usize = input.next("a length")?;
        // The length is the file's word: grow as items arrive rather than trusting it.
        let mut v = Vec::new();
        for _ in 0..n {
            v.push(T::read(input)?);
        }
        Ok(v)
    }
}

impl<A: Record, B: Record> Record for (A, B) {
    fn write(&self, out: &mut Line) {
        self.0.write(out);
        self.1.write(out);
    }
    fn read(input: &mut Fields) -> Result<(A, B), String> {
        Ok((A::read(input)?, B::read(input)?))
    }
}

impl Record for Point2<f32> {
    fn write(&self, out: &mut Line) {
        self.x.write(out);
        self.y.write(out);
    }
    fn read(input: &mut Fields) -> Result<Point2<f32>, String> {
        Ok(Point2::new(f32::read(input)?, f32::read(input)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// Every bit pattern (NaN's payload aside) reads back as itself.
    #[test]
    fn numbers_survive_the_trip_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut xs: Vec<f64> = (0..20_000)
            .map(|_| f64::from_bits(rng.random::<u64>()))
            .collect();
        xs.extend([
            0.0,
            -0.0,
            0.1,
            1.0 / 3.0,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e15,
            1e16,
            123_456.789,
        ]);
        for x in xs {
            let back: f64 = from_line(&to_line(&x)).unwrap();
            assert!(
                back.to_bits() == x.to_bits() || (x.is_nan() && back.is_nan()),
                "{x:?} came back as {back:?}"
            );
        }
        for _ in 0..20_000 {
            let x = f32::from_bits(rng.random::<u32>());
            let back: f32 = from_line(&to_line(&x)).unwrap();
            assert!(back.to_bits() == x.to_bits() || (x.is_nan() && back.is_nan()));
        }
    }

    #[test]
    fn lists_options_and_pairs_read_back_and_a_bad_line_is_named() {
        let r: (Vec<Option<f64>>, (u32, Point2<f32>)) = (
            vec![Some(0.5), None, Some(-2.0)],
            (7, Point2::new(1.5, -0.25)),
        );
        let line = to_line(&r);
        assert_eq!(line, "3 0.5 - -2.0 7 1.5 -0.25");
        assert_eq!(
            from_line::<(Vec<Option<f64>>, (u32, Point2<f32>))>(&line),
            Ok(r)
        );
        assert_eq!(
            from_line::<(f64, f64)>("1.0"),
            Err("field 2 (a number) is missing".into())
        );
        assert_eq!(
            from_line::<f64>("1.0 2.0"),
            Err("\"2.0\" after the 1 fields a run has".into())
        );
        assert_eq!(
            from_line::<u32>("x"),
            Err("field 1 (a count): \"x\" is not a count".into())
        );
    }
}
