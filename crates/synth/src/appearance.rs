//! What a scene looks like: the hand's colour (gloves of several colours, bare skin of several
//! tones), the tool's finish, the table's surface (a drape, wood, a printed mat, a steel tray,
//! clutter), the light (direction, strength, colour, slow colour drift) and whether the hand casts
//! shadows. Presets by name and seeded random looks, so that nothing is tuned to one appearance.

use nalgebra::Vector3;

use crate::render::Light;
use crate::texture::{drape_albedo, mix64, value_noise};

/// The table's surface: an albedo function of the table position (x, y), metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Background {
    /// A green surgical drape with mottling, weave and folds.
    Drape,
    /// A light wooden table top with grain.
    Wood,
    /// A printed cutting mat: 1 cm squares in two greys with darker grid lines.
    Mat,
    /// A brushed steel tray (about the tool's own grey).
    Steel,
    /// A blue drape strewn with flat clutter (paper, gauze, tape, coloured tags), seeded.
    Clutter(u64),
}

impl Background {
    /// The albedo at table position (x, y), linear 0..1 per channel.
    pub fn albedo(&self, x: f64, y: f64) -> [f32; 3] {
        match *self {
            Background::Drape => drape_albedo(x, y),
            Background::Wood => {
                let warp = 0.004 * value_noise(x / 0.05, y / 0.02, 21);
                let grain = (std::f64::consts::TAU * (y + warp) / 0.0045).sin();
                let f = 1.0 + 0.10 * grain + 0.08 * value_noise(x / 0.08, y / 0.01, 23);
                [0.62, 0.45, 0.30].map(|c| c * f as f32)
            }
            Background::Mat => {
                let cell = |v: f64| (v / 0.01).floor() as i64;
                let light = (cell(x) + cell(y)).rem_euclid(2) == 0;
                let line = |v: f64| (v / 0.01 - (v / 0.01).round()).abs() < 0.05;
                let base = if line(x) || line(y) {
                    0.18
                } else if light {
                    0.55
                } else {
                    0.42
                };
                let f = 1.0 + 0.03 * value_noise(x / 0.004, y / 0.004, 29);
                [base, base * 1.02, base * 0.97].map(|c| (c * f) as f32)
            }
            Background::Steel => {
                let brush = 0.04 * value_noise(x / 0.0015, y / 0.05, 31);
                let f = (1.0 + brush + 0.05 * value_noise(x / 0.1, y / 0.1, 33)) as f32;
                [0.52 * f, 0.53 * f, 0.55 * f]
            }
            Background::Clutter(seed) => {
                let base = [0.16, 0.30, 0.52];
                let mottle = 1.0 + 0.06 * value_noise(x / 0.02, y / 0.02, 37);
                let mut colour = base.map(|c| (c * mottle) as f32);
                // Items on a 6 cm grid: each cell holds at most one item, a rectangle or a disc.
                let (gx, gy) = ((x / 0.06).floor() as i64, (y / 0.06).floor() as i64);
                let h = mix64(seed ^ mix64((gx as u64).wrapping_mul(0x9e37_79b9) ^ (gy as u64) << 32));
                if !h.is_multiple_of(3) {
                    let u = |k: u32| ((h >> (8 * k)) & 0xff) as f64 / 255.0;
                    let (cx, cy) = ((gx as f64 + 0.2 + 0.6 * u(1)) * 0.06, (gy as f64 + 0.2 + 0.6 * u(2)) * 0.06);
                    let (hw, hh) = (0.008 + 0.02 * u(3), 0.006 + 0.015 * u(4));
                    let inside = if h & 0x100_0000_0000 == 0 {
                        (x - cx).abs() < hw && (y - cy).abs() < hh
                    } else {
                        (x - cx).hypot(y - cy) < hw
                    };
                    if inside {
                        // Paper, gauze, skin-toned tape, a red tag, a yellow tag, a steel clip.
                        const ITEMS: [[f32; 3]; 6] = [
                            [0.85, 0.85, 0.82],
                            [0.92, 0.90, 0.86],
                            [0.78, 0.58, 0.45],
                            [0.70, 0.12, 0.10],
                            [0.85, 0.75, 0.15],
                            [0.55, 0.55, 0.57],
                        ];
                        colour = ITEMS[(u(5) * 6.0).min(5.0) as usize];
                    }
                }
                colour
            }
        }
    }

    /// A short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            Background::Drape => "drape",
            Background::Wood => "wood",
            Background::Mat => "mat",
            Background::Steel => "steel",
            Background::Clutter(_) => "clutter",
        }
    }
}

/// How a scene looks. See the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct Appearance {
    /// The preset's name (or `random:SEED`).
    pub name: String,
    /// The hand's albedo (glove or skin), linear 0..1.
    pub hand: [f32; 3],
    /// The handle's albedo.
    pub handle: [f32; 3],
    /// The blade's albedo.
    pub blade: [f32; 3],
    /// The table's surface.
    pub background: Background,
    /// The light.
    pub light: Light,
    /// The light's colour, per channel (1 = white).
    pub light_colour: [f32; 3],
    /// Relative amplitude of a slow drift of the light's colour over the recording (per channel,
    /// out of phase: a change no global exposure gain explains).
    pub colour_drift: f32,
    /// The hand and tool cast shadows on the table.
    pub shadows: bool,
}

/// Albedos of the looks, linear 0..1.
mod albedo {
    pub const BLUE_NITRILE: [f32; 3] = [60.0 / 255.0, 110.0 / 255.0, 200.0 / 255.0];
    pub const PURPLE_NITRILE: [f32; 3] = [0.42, 0.26, 0.62];
    pub const WHITE_LATEX: [f32; 3] = [0.86, 0.84, 0.76];
    pub const SKIN_LIGHT: [f32; 3] = [0.88, 0.68, 0.58];
    pub const SKIN_MEDIUM: [f32; 3] = [0.66, 0.46, 0.33];
    pub const SKIN_DARK: [f32; 3] = [0.34, 0.22, 0.16];
    pub const STEEL: [f32; 3] = [150.0 / 255.0, 150.0 / 255.0, 155.0 / 255.0];
    pub const POLISHED: [f32; 3] = [205.0 / 255.0, 205.0 / 255.0, 210.0 / 255.0];
    pub const BLACK_COATED: [f32; 3] = [0.10, 0.10, 0.11];
    pub const BRASS: [f32; 3] = [0.72, 0.58, 0.26];
    pub const BLUE_ANODIZED: [f32; 3] = [0.15, 0.32, 0.62];
    pub const DULL_BLADE: [f32; 3] = [0.62, 0.62, 0.64];
}

impl Appearance {
    /// The presets' names, for help texts.
    pub const NAMES: &'static str = "classic, purple-nitrile, latex, skin-light, skin-medium, skin-dark, random:SEED";

    /// The classic look of the built-in scene: a blue nitrile glove, a steel scalpel, a green
    /// drape, no cast shadows.
    pub fn classic() -> Self {
        Appearance {
            name: "classic".to_owned(),
            hand: albedo::BLUE_NITRILE,
            handle: albedo::STEEL,
            blade: albedo::POLISHED,
            background: Background::Drape,
            light: Light::default(),
            light_colour: [1.0; 3],
            colour_drift: 0.0,
            shadows: false,
        }
    }

    /// A preset by name, or `random:SEED`.
    pub fn from_name(name: &str) -> Option<Self> {
        if let Some(seed) = name.strip_prefix("random:") {
            return seed.parse().ok().map(Self::random);
        }
        let light = |x: f64, y: f64, ambient: f32| Light {
            direction: Vector3::new(x, y, 1.0).normalize(),
            ambient,
            diffuse: 1.0 - ambient,
        };
        let base = Self { name: name.to_owned(), shadows: true, colour_drift: 0.02, ..Self::classic() };
        Some(match name {
            "classic" => Self::classic(),
            "purple-nitrile" => Self {
                hand: albedo::PURPLE_NITRILE,
                background: Background::Wood,
                light: light(-0.4, 0.2, 0.35),
                light_colour: [1.0, 0.97, 0.92],
                ..base
            },
            "latex" => Self {
                hand: albedo::WHITE_LATEX,
                handle: albedo::BLACK_COATED,
                background: Background::Mat,
                light: light(0.3, 0.45, 0.4),
                light_colour: [1.0, 0.94, 0.85],
                ..base
            },
            "skin-light" => Self {
                hand: albedo::SKIN_LIGHT,
                background: Background::Clutter(11),
                light: light(0.5, -0.1, 0.3),
                ..base
            },
            "skin-medium" => Self {
                hand: albedo::SKIN_MEDIUM,
                handle: albedo::BRASS,
                background: Background::Drape,
                light: light(-0.2, -0.5, 0.45),
                light_colour: [0.95, 0.98, 1.0],
                ..base
            },
            "skin-dark" => Self {
                hand: albedo::SKIN_DARK,
                handle: albedo::BLUE_ANODIZED,
                blade: albedo::DULL_BLADE,
                background: Background::Steel,
                light: light(0.1, 0.35, 0.35),
                ..base
            },
            _ => return None,
        })
    }

    /// A seeded random look: a hand between glove colours and skin tones, a tool finish, a
    /// background, a light from a random direction with a random colour, shadows on.
    pub fn random(seed: u64) -> Self {
        let mut state = mix64(seed ^ 0xa99e_a7a2_ce00);
        let mut u = move || {
            state = mix64(state);
            (state >> 11) as f32 / (1u64 << 53) as f32
        };
        let hands = [
            albedo::BLUE_NITRILE,
            albedo::PURPLE_NITRILE,
            albedo::WHITE_LATEX,
            albedo::SKIN_LIGHT,
            albedo::SKIN_MEDIUM,
            albedo::SKIN_DARK,
        ];
        // Mix two neighbouring hand colours, then scale: any glove or skin in between.
        let k = (u() * (hands.len() - 1) as f32) as usize;
        let t = u();
        let scale = 0.85 + 0.3 * u();
        let hand: [f32; 3] =
            std::array::from_fn(|c| ((hands[k][c] * (1.0 - t) + hands[k + 1][c] * t) * scale).clamp(0.02, 0.95));
        let handles = [albedo::STEEL, albedo::BLACK_COATED, albedo::BRASS, albedo::BLUE_ANODIZED];
        let handle = handles[((u() * 4.0) as usize).min(3)];
        let blade = if u() < 0.5 { albedo::POLISHED } else { albedo::DULL_BLADE };
        let backgrounds =
            [Background::Drape, Background::Wood, Background::Mat, Background::Steel, Background::Clutter(seed)];
        let background = backgrounds[((u() * 5.0) as usize).min(4)];
        let azimuth = f64::from(u()) * std::f64::consts::TAU;
        let tilt = 0.2 + 0.5 * f64::from(u());
        let ambient = 0.25 + 0.25 * u();
        Appearance {
            name: format!("random:{seed}"),
            hand,
            handle,
            blade,
            background,
            light: Light {
                direction: Vector3::new(tilt * azimuth.cos(), tilt * azimuth.sin(), 1.0).normalize(),
                ambient,
                diffuse: 1.0 - ambient,
            },
            light_colour: [0.92 + 0.08 * u(), 0.92 + 0.08 * u(), 0.92 + 0.08 * u()],
            colour_drift: 0.03 * u(),
            shadows: true,
        }
    }

    /// The light's colour gains at time `t` seconds: its colour times a slow drift, each channel
    /// on its own phase.
    pub fn colour_gains(&self, t: f64) -> [f32; 3] {
        std::array::from_fn(|c| {
            let phase = std::f64::consts::TAU * (t / 7.0 + c as f64 / 3.0);
            self.light_colour[c] * (1.0 + self.colour_drift * phase.sin() as f32)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_differ_and_random_looks_are_seeded() {
        let names = ["classic", "purple-nitrile", "latex", "skin-light", "skin-medium", "skin-dark"];
        let looks: Vec<Appearance> = names.iter().map(|n| Appearance::from_name(n).expect(n)).collect();
        for (i, a) in looks.iter().enumerate() {
            for b in &looks[..i] {
                assert_ne!(a.hand, b.hand, "{} and {} share a hand colour", a.name, b.name);
            }
        }
        assert_eq!(Appearance::random(3), Appearance::random(3));
        assert_ne!(Appearance::random(3).hand, Appearance::random(4).hand);
        assert_eq!(Appearance::from_name("random:3"), Some(Appearance::random(3)));
        assert_eq!(Appearance::from_name("green-glove"), None);
    }

    #[test]
    fn backgrounds_have_texture() {
        for b in [Background::Drape, Background::Wood, Background::Mat, Background::Steel, Background::Clutter(1)] {
            let samples: Vec<f32> = (0..400).map(|k| b.albedo(k as f64 * 0.0007, k as f64 * 0.0011)[1]).collect();
            let mean = samples.iter().sum::<f32>() / samples.len() as f32;
            let var = samples.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / samples.len() as f32;
            assert!(var > 1e-5, "{} is flat", b.name());
            assert!(samples.iter().all(|v| (0.0..=1.0).contains(v)));
        }
    }
}
