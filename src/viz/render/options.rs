//! What a picture shows and how: the style, the colouring field and its range, the walls, the
//! size; and the parsers of the command line's resolution and colour range.

use clap::ValueEnum;

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum, Default)]
pub enum Style {
    /// Shaded spheres coloured by a field.
    #[default]
    Particles,
    /// A smoothed liquid surface (screen-space fluid rendering).
    Surface,
    /// The fluid surface reconstructed as a triangle mesh (as `--surface-mesh-every` writes it),
    /// shaded; for frame dumps.
    Mesh,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum, Default)]
pub enum ColorBy {
    #[default]
    Speed,
    Density,
    Pressure,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum, Default)]
pub enum Walls {
    /// Translucent, so the fluid shows through them.
    #[default]
    Faint,
    /// Not drawn.
    Hidden,
    /// Opaque.
    Solid,
}

/// What a picture shows and how.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub style: Style,
    pub color_by: ColorBy,
    /// A fixed colour range; None: each frame's smallest to largest value.
    pub range: Option<(f32, f32)>,
    pub walls: Walls,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions { width: 1280, height: 720, style: Style::Particles, color_by: ColorBy::Speed, range: None, walls: Walls::Faint }
    }
}

/// Parses `WIDTHxHEIGHT`.
pub fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let err = || format!("'{s}' is not a resolution; write WIDTHxHEIGHT with each between 16 and 8192, e.g. 1280x720");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(err)?;
    let w: u32 = w.trim().parse().map_err(|_| err())?;
    let h: u32 = h.trim().parse().map_err(|_| err())?;
    if !(16..=8192).contains(&w) || !(16..=8192).contains(&h) {
        return Err(err());
    }
    Ok((w, h))
}

/// Parses `MIN:MAX` for a fixed colour range.
pub fn parse_range(s: &str) -> Result<(f32, f32), String> {
    // The picture colours in f32: a bound beyond its range (3.4e38) is no finite colour.
    // The shader divides by MAX - MIN: that too must be a finite f32.
    let err = || format!("'{s}' is not a colour range; write MIN:MAX with MIN < MAX, each within +-3.4e38 (f32) and MAX - MIN below 3.4e38 too, e.g. 0:2.5");
    let (a, b) = s.split_once(':').ok_or_else(err)?;
    let a: f32 = a.trim().parse().map_err(|_| err())?;
    let b: f32 = b.trim().parse().map_err(|_| err())?;
    if !(a.is_finite() && b.is_finite() && a < b && (b - a).is_finite()) {
        return Err(err());
    }
    Ok((a, b))
}
