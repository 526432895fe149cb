//! Writes the suite's figures. Plots are drawn once as SVG (plotters' SVG backend needs no
//! fonts); the PNG beside it is rendered from that SVG with resvg and the system fonts, so the
//! two files always show the same picture.

pub mod engagement;
pub mod progress;

use std::path::{Path, PathBuf};

/// Why a figure could not be written.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    #[error("the SVG for {path} does not parse: {reason}")]
    BadSvg { path: PathBuf, reason: String },
    #[error("cannot allocate a {width}x{height} pixmap for {path}")]
    Pixmap {
        path: PathBuf,
        width: u32,
        height: u32,
    },
    #[error("encoding {path} as PNG: {reason}")]
    Png { path: PathBuf, reason: String },
    #[error("writing {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Renders an SVG document to PNG bytes at `scale` (1.0 = the SVG's own size).
pub fn svg_to_png(svg: &str, scale: f32, name_for_errors: &Path) -> Result<Vec<u8>, FigureError> {
    render(svg, scale, name_for_errors)?
        .encode_png()
        .map_err(|e| FigureError::Png {
            path: name_for_errors.to_path_buf(),
            reason: e.to_string(),
        })
}

fn render(
    svg: &str,
    scale: f32,
    name_for_errors: &Path,
) -> Result<resvg::tiny_skia::Pixmap, FigureError> {
    let mut options = resvg::usvg::Options::default();
    options.fontdb_mut().load_system_fonts();
    // plotters names the generic "sans-serif", which fontdb does not map to an installed face
    // by itself: point the generic families at DejaVu (Debian's fonts-dejavu-core).
    options.font_family = "DejaVu Sans".to_string();
    let fonts = options.fontdb_mut();
    fonts.set_sans_serif_family("DejaVu Sans");
    fonts.set_serif_family("DejaVu Serif");
    fonts.set_monospace_family("DejaVu Sans Mono");
    let tree = resvg::usvg::Tree::from_str(svg, &options).map_err(|e| FigureError::BadSvg {
        path: name_for_errors.to_path_buf(),
        reason: e.to_string(),
    })?;
    let size = tree
        .size()
        .to_int_size()
        .scale_by(scale)
        .ok_or(FigureError::Pixmap {
            path: name_for_errors.to_path_buf(),
            width: 0,
            height: 0,
        })?;
    let mut pixmap =
        resvg::tiny_skia::Pixmap::new(size.width(), size.height()).ok_or(FigureError::Pixmap {
            path: name_for_errors.to_path_buf(),
            width: size.width(),
            height: size.height(),
        })?;
    pixmap.fill(resvg::tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::from_scale(scale, scale),
        &mut pixmap.as_mut(),
    );
    Ok(pixmap)
}

/// Writes `<stem>.svg` and `<stem>.png` and returns both paths. Each file is written to a
/// temporary name first and renamed, so a reader never sees half a figure.
pub fn write_svg_and_png(stem: &Path, svg: &str) -> Result<(PathBuf, PathBuf), FigureError> {
    let svg_path = stem.with_extension("svg");
    let png_path = stem.with_extension("png");
    write_atomically(&svg_path, svg.as_bytes())?;
    let png = svg_to_png(svg, 1.5, &png_path)?;
    write_atomically(&png_path, &png)?;
    Ok((svg_path, png_path))
}

fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), FigureError> {
    atomic_file::write(path, bytes).map_err(|source| FigureError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_text_and_shapes_to_png() {
        let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="120" height="40">
            <rect x="0" y="0" width="60" height="40" fill="red"/>
            <text x="65" y="25" font-family="sans-serif" font-size="14">E|L</text></svg>"#;
        let png = svg_to_png(svg, 1.0, Path::new("t.png")).expect("renders");
        assert_eq!(&png[1..4], b"PNG");
        assert!(png.len() > 100);
    }

    #[test]
    fn generic_sans_serif_text_is_drawn() {
        // plotters writes font-family="sans-serif": it must resolve to a real face.
        let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="200" height="40">
            <text x="5" y="30" font-family="sans-serif" font-size="24">Engagement</text></svg>"#;
        let pixmap = render(svg, 1.0, Path::new("t.png")).expect("renders");
        let inked = pixmap.pixels().iter().filter(|p| p.red() < 128).count();
        assert!(
            inked > 100,
            "only {inked} dark pixels: the text was not drawn"
        );
    }

    #[test]
    fn bad_svg_is_a_named_error() {
        let err = svg_to_png("<svg", 1.0, Path::new("broken.png")).unwrap_err();
        assert!(err.to_string().contains("broken.png"), "{err}");
    }
}
