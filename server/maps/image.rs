//! The images a ROS map names: PGM (binary `P5` and plain `P2`) read and written by hand,
//! PNG through the `png` crate.
//!
//! PGM is a text header of three numbers and a raster of samples; a parser of our own is a
//! page, bounds every size before allocating, names the line of a bad header, and spares a
//! dependency. PNG needs inflate and filters, so a crate does it.
//!
//! Pixels are kept the way SDL_image hands them to map_server: 1 channel for grey, 3 for
//! colour, 4 for colour with alpha (grey with alpha becomes colour with alpha).

use std::io::Cursor;

use crate::maps::format::{MAX_CELLS, Problem};

/// A decoded image, rows from the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    /// 1 (grey), 3 (RGB) or 4 (RGBA).
    pub channels: usize,
    /// `width × height × channels` samples of 0 to 255, row by row from the top.
    pub samples: Vec<u8>,
}

impl Image {
    /// Whether the last channel is alpha.
    pub fn has_alpha(&self) -> bool {
        self.channels == 4
    }

    /// The samples of pixel (`x`, `y`), `y` counted from the top.
    pub fn pixel(&self, x: usize, y: usize) -> &[u8] {
        let at = (y * self.width + x) * self.channels;
        &self.samples[at..at + self.channels]
    }
}

/// Decodes a PGM or PNG image, told apart by their first bytes (not by the file's name).
pub fn decode(bytes: &[u8]) -> Result<Image, Problem> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        decode_png(bytes)
    } else if bytes.starts_with(b"P5") || bytes.starts_with(b"P2") {
        decode_pgm(bytes)
    } else if bytes.starts_with(b"P") && bytes.len() > 1 && bytes[1].is_ascii_digit() {
        Err(Problem::line(
            1,
            format!(
                "a P{} Netpbm image; only greyscale PGM (P5 or P2) is read: convert it to PGM or \
                 PNG",
                bytes[1] as char
            ),
        ))
    } else {
        Err(Problem::Content(
            "not a PGM (P5 or P2) or PNG image: map_server reads other formats through \
             SDL_image; convert it to PGM or PNG"
                .into(),
        ))
    }
}

fn check_size(width: usize, height: usize) -> Result<(), Problem> {
    if width == 0 || height == 0 {
        return Err(Problem::Content(format!(
            "the image is {width} × {height} pixels"
        )));
    }
    match width.checked_mul(height) {
        Some(n) if n <= MAX_CELLS => Ok(()),
        _ => Err(Problem::Content(format!(
            "the image is {width} × {height} pixels, the limit is {MAX_CELLS} pixels \
             (4096 × 4096)"
        ))),
    }
}

/// Reads the whitespace-separated tokens of a PGM, skipping `#` comments, with line numbers.
struct Tokens<'a> {
    bytes: &'a [u8],
    at: usize,
    line: usize,
}

impl<'a> Tokens<'a> {
    /// The next token and the line it is on, or `None` at the end.
    fn next(&mut self) -> Option<(&'a [u8], usize)> {
        loop {
            let b = *self.bytes.get(self.at)?;
            if b == b'#' {
                while self.bytes.get(self.at).is_some_and(|&b| b != b'\n') {
                    self.at += 1;
                }
            } else if b.is_ascii_whitespace() {
                if b == b'\n' {
                    self.line += 1;
                }
                self.at += 1;
            } else {
                break;
            }
        }
        let start = self.at;
        while self
            .bytes
            .get(self.at)
            .is_some_and(|b| !b.is_ascii_whitespace() && *b != b'#')
        {
            self.at += 1;
        }
        Some((&self.bytes[start..self.at], self.line))
    }

    /// The next token as a number in `1..=max`, `what` naming it in errors.
    fn number(&mut self, what: &str, max: usize) -> Result<usize, Problem> {
        let Some((token, line)) = self.next() else {
            return Err(Problem::line(
                self.line,
                format!("the file ends before the {what}"),
            ));
        };
        let text = String::from_utf8_lossy(token);
        match text.parse::<usize>() {
            Ok(n) if (1..=max).contains(&n) => Ok(n),
            _ => Err(Problem::line(
                line,
                format!(
                    "{what}: expected a whole number from 1 to {max}, found {:?}",
                    text.chars().take(20).collect::<String>()
                ),
            )),
        }
    }
}

/// Decodes a binary (`P5`) or plain (`P2`) PGM. Samples are scaled to 0..=255 as SDL_image
/// does (`value × 255 / maxval`, rounded down), so thresholds mean the same at any maxval.
pub fn decode_pgm(bytes: &[u8]) -> Result<Image, Problem> {
    let binary = bytes.starts_with(b"P5");
    let mut tokens = Tokens {
        bytes,
        at: 2,
        line: 1,
    };
    let width = tokens.number("width", MAX_CELLS)?;
    let height = tokens.number("height", MAX_CELLS)?;
    let maxval = tokens.number("maxval", 65_535)?;
    check_size(width, height)?;
    let n = width * height;
    let scale = |v: usize| (v * 255 / maxval) as u8;
    let mut samples = Vec::with_capacity(n);
    if binary {
        // Exactly one whitespace byte ends the header; the raster follows.
        let start = tokens.at + 1;
        let wide = maxval > 255;
        let need = n * if wide { 2 } else { 1 };
        let raster = bytes.get(start..).unwrap_or_default();
        if raster.len() < need {
            return Err(Problem::Content(format!(
                "the P5 raster has {} bytes, {width} × {height} pixels need {need}",
                raster.len()
            )));
        }
        for k in 0..n {
            let v = if wide {
                usize::from(u16::from_be_bytes([raster[2 * k], raster[2 * k + 1]]))
            } else {
                usize::from(raster[k])
            };
            if v > maxval {
                return Err(Problem::Content(format!(
                    "pixel {k} is {v}, above the maxval {maxval}"
                )));
            }
            samples.push(scale(v));
        }
    } else {
        for k in 0..n {
            let Some((token, line)) = tokens.next() else {
                return Err(Problem::line(
                    tokens.line,
                    format!("the file ends after {k} of {n} pixels"),
                ));
            };
            let text = String::from_utf8_lossy(token);
            match text.parse::<usize>() {
                Ok(v) if v <= maxval => samples.push(scale(v)),
                _ => {
                    return Err(Problem::line(
                        line,
                        format!(
                            "pixel {k}: expected a whole number from 0 to {maxval}, found {:?}",
                            text.chars().take(20).collect::<String>()
                        ),
                    ));
                }
            }
        }
    }
    Ok(Image {
        width,
        height,
        channels: 1,
        samples,
    })
}

/// Decodes a PNG by colour value: palettes and bit depths under 8 expanded, 16-bit samples
/// cut to their high byte (as SDL_image does), a `tRNS` chunk made an alpha channel. Memory
/// is bounded before the pixels are read.
pub fn decode_png(bytes: &[u8]) -> Result<Image, Problem> {
    let bad = |e: png::DecodingError| Problem::Content(format!("PNG: {e}"));
    let limits = png::Limits {
        bytes: 8 * MAX_CELLS,
    };
    let mut decoder = png::Decoder::new_with_limits(Cursor::new(bytes), limits);
    let info = decoder.read_header_info().map_err(bad)?;
    check_size(info.width as usize, info.height as usize)?;
    decoder.set_transformations(png::Transformations::normalize_to_color8());
    let mut reader = decoder.read_info().map_err(bad)?;
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| Problem::Content("PNG: the image is too large".into()))?;
    let mut buf = vec![0; size];
    let frame = reader.next_frame(&mut buf).map_err(bad)?;
    let (width, height) = (frame.width as usize, frame.height as usize);
    buf.truncate(frame.buffer_size());
    let line = frame.line_size;
    let (channels, samples) = match frame.color_type {
        png::ColorType::Grayscale => (1, packed(&buf, line, width, 1)),
        png::ColorType::Rgb => (3, packed(&buf, line, width, 3)),
        png::ColorType::Rgba => (4, packed(&buf, line, width, 4)),
        png::ColorType::GrayscaleAlpha => {
            let ga = packed(&buf, line, width, 2);
            let rgba = ga
                .chunks_exact(2)
                .flat_map(|p| [p[0], p[0], p[0], p[1]])
                .collect();
            (4, rgba)
        }
        png::ColorType::Indexed => {
            return Err(Problem::Content(
                "PNG: a palette image was not expanded".into(),
            ));
        }
    };
    if samples.len() != width * height * channels {
        return Err(Problem::Content(format!(
            "PNG: {} samples for {width} × {height} pixels",
            samples.len()
        )));
    }
    Ok(Image {
        width,
        height,
        channels,
        samples,
    })
}

/// The rows of a decoded frame without any padding at their ends.
fn packed(buf: &[u8], line: usize, width: usize, channels: usize) -> Vec<u8> {
    let used = width * channels;
    if line == used {
        return buf.to_vec();
    }
    buf.chunks(line.max(1))
        .flat_map(|row| row.get(..used).unwrap_or(row).iter().copied())
        .collect()
}

/// A binary PGM (`P5`, maxval 255) of grey `samples`, rows from the top, with a comment
/// saying where it came from, as map_saver writes one.
pub fn encode_pgm(width: usize, height: usize, samples: &[u8], comment: &str) -> Vec<u8> {
    let mut out = format!("P5\n# {comment}\n{width} {height}\n255\n").into_bytes();
    out.extend_from_slice(samples);
    out
}

/// A greyscale PNG of `samples`, rows from the top.
pub fn encode_png(width: usize, height: usize, samples: &[u8]) -> Result<Vec<u8>, Problem> {
    let mut out = Vec::new();
    let bad = |e: png::EncodingError| Problem::Content(format!("PNG: {e}"));
    let mut encoder = png::Encoder::new(&mut out, width as u32, height as u32);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(bad)?;
    writer.write_image_data(samples).map_err(bad)?;
    writer.finish().map_err(bad)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binary_and_plain_pgm_read_the_same_pixels() {
        let p5 = encode_pgm(3, 2, &[0, 128, 255, 254, 205, 1], "test");
        let p2 = b"P2\n# a comment\n3 2\n255\n0 128 255\n254 205 1\n";
        let a = decode(&p5).unwrap();
        let b = decode(p2).unwrap();
        assert_eq!(a, b);
        assert_eq!((a.width, a.height, a.channels), (3, 2, 1));
        assert_eq!(a.pixel(1, 1), &[205]);
    }

    #[test]
    fn a_small_maxval_is_scaled_to_255_and_sixteen_bits_are_read() {
        let img = decode(b"P2 2 1 15 0 15").unwrap();
        assert_eq!(img.samples, vec![0, 255]);
        let mut p5 = b"P5 2 1 1000\n".to_vec();
        p5.extend_from_slice(&[0x01, 0xF4, 0x03, 0xE8]); // 500 and 1000
        assert_eq!(decode(&p5).unwrap().samples, vec![127, 255]);
    }

    #[test]
    fn malformed_pgm_headers_name_the_line() {
        let cases: [(&[u8], &str); 7] = [
            (b"P5\n3", "line 2: the file ends before the height"),
            (
                b"P2\n# c\nx 2 255\n",
                "line 3: width: expected a whole number",
            ),
            (
                b"P5 3 2 0\n",
                "line 1: maxval: expected a whole number from 1 to 65535",
            ),
            (b"P5 3 2 255\n\x00\x01", "the P5 raster has 2 bytes"),
            (
                b"P2 2 1 255\n0\n300",
                "line 3: pixel 1: expected a whole number from 0 to 255",
            ),
            (b"P2 2 1 255 0", "line 1: the file ends after 1 of 2 pixels"),
            (b"P6 1 1 255 000", "only greyscale PGM"),
        ];
        for (bytes, want) in cases {
            let e = decode(bytes).unwrap_err().to_string();
            assert!(e.contains(want), "{e:?} lacks {want:?}");
        }
        let huge = decode(b"P5 5000 5000 255\n").unwrap_err().to_string();
        assert!(huge.contains("the limit is"), "{huge}");
        assert!(decode(b"GIF89a").is_err());
    }

    #[test]
    fn png_round_trips_and_grey_alpha_becomes_rgba() {
        let png = encode_png(2, 2, &[0, 64, 128, 255]).unwrap();
        let img = decode(&png).unwrap();
        assert_eq!(
            (img.channels, img.samples.clone()),
            (1, vec![0, 64, 128, 255])
        );

        let mut out = Vec::new();
        let mut enc = png::Encoder::new(&mut out, 1, 1);
        enc.set_color(png::ColorType::GrayscaleAlpha);
        let mut w = enc.write_header().unwrap();
        w.write_image_data(&[10, 200]).unwrap();
        w.finish().unwrap();
        let img = decode(&out).unwrap();
        assert_eq!((img.channels, img.samples), (4, vec![10, 10, 10, 200]));
        assert!(decode(&out[..out.len() / 2]).is_err());
    }
}
