//! Output — shared plumbing for the plots (`profile.png`, the trace fan and transfer curves).
//! In: nothing (the vendored font) or an RGB8 buffer. Out: the font registered with plotters once
//! per process, and PNG bytes.

use std::sync::OnceLock;

use image::ImageEncoder;

/// The font family name the plots ask plotters for.
pub const PLOT_FONT: &str = "sans-serif";

/// Register the vendored DejaVu Sans (assets/fonts) as [`PLOT_FONT`], once per process, so plots
/// look the same on every machine whatever fonts it has installed.
pub fn register_plot_font() -> Result<(), String> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font(
            PLOT_FONT,
            plotters::style::FontStyle::Normal,
            include_bytes!("../../assets/fonts/DejaVuSans.ttf"),
        )
        .is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err("the vendored font assets/fonts/DejaVuSans.ttf does not load".into())
    }
}

/// Encode an 8-bit RGB buffer (row-major, `width × height × 3` bytes, as plotters' bitmap backend
/// draws it) as PNG bytes.
pub fn rgb8_to_png(buffer: &[u8], width: u32, height: u32) -> Result<Vec<u8>, String> {
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(buffer, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| e.to_string())?;
    Ok(png)
}
