//! PNG charts without system fonts or libraries: the embedded font, a pixel buffer and PNG
//! encoding, shared by the learning curve (`train/curve.rs`) and the HPO trajectory
//! (`hpo/plot.rs`).

use std::sync::OnceLock;

use plotters::backend::RGBPixel;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

const FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

/// What a chart draws on: a white `width` x `height` RGB picture.
pub type Canvas<'a> = DrawingArea<BitMapBackend<'a, RGBPixel>, Shift>;

/// Registers the embedded font as "sans-serif" (once per process).
fn register_embedded_font() -> Result<(), String> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            register_font("sans-serif", FontStyle::Normal, FONT)
                .map_err(|_| "the embedded font does not load".to_owned())
        })
        .clone()
}

/// Renders a chart: `draw` draws on a white canvas; the result is PNG bytes. Errors of the
/// drawing library and of the encoder become `error(text)`.
pub fn render_png<E>(
    width: u32,
    height: u32,
    error: impl Fn(String) -> E,
    draw: impl FnOnce(&Canvas<'_>) -> Result<(), E>,
) -> Result<Vec<u8>, E> {
    register_embedded_font().map_err(&error)?;
    let text = |e: &dyn std::fmt::Display| error(e.to_string());
    let mut buffer = vec![255u8; (width * height * 3) as usize];
    {
        let backend =
            BitMapBackend::<RGBPixel>::with_buffer_and_format(&mut buffer, (width, height))
                .map_err(|e| text(&e))?;
        let root = backend.into_drawing_area();
        root.fill(&WHITE).map_err(|e| text(&e))?;
        draw(&root)?;
        root.present().map_err(|e| text(&e))?;
    }
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| text(&e))?;
        writer.write_image_data(&buffer).map_err(|e| text(&e))?;
        writer.finish().map_err(|e| text(&e))?;
    }
    Ok(out)
}
