//! `rally plot`: learning curves of one or more training runs (reward, hit rate and success rate
//! against control steps, one line per run) as a PNG, drawn with plotters. Text is set in DejaVu
//! Sans 2.37, built into the binary (the `dejavu` crate), so a figure needs no system font;
//! `RALLY_FONT` names another TrueType file.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use agents::ppo::store::read_curve;
use agents::ppo::trainer::CurveRow;
use anyhow::anyhow;
use clap::Args;
use plotters::prelude::*;

use super::CliError;

/// One run's curve and its legend label.
pub struct Series {
    /// Legend label.
    pub label: String,
    /// The rows.
    pub rows: Vec<CurveRow>,
}

/// Registers the font once: `RALLY_FONT`'s file if set, else the built-in DejaVu Sans. The
/// error names the file.
fn font() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        let (bytes, from): (&'static [u8], String) = match std::env::var_os("RALLY_FONT") {
            Some(path) => {
                let path = PathBuf::from(path);
                let bytes = std::fs::read(&path)
                    .map_err(|e| format!("RALLY_FONT={}: {e}", path.display()))?;
                (
                    Box::leak(bytes.into_boxed_slice()),
                    format!("RALLY_FONT={}", path.display()),
                )
            }
            None => (dejavu::sans::regular(), "the built-in DejaVu Sans".into()),
        };
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| format!("{from}: not a usable TrueType font"))
    })
    .clone()
}

/// Draws a white `size` canvas with `draw` and writes it to `out` as a PNG.
fn draw_png(
    out: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend, plotters::coord::Shift>) -> Result<(), String>,
) -> Result<(), String> {
    let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        draw(&root)?;
        root.present().map_err(|e| e.to_string())?;
    }
    write_png(out, size, &rgb)
}

/// Writes an RGB image losslessly at the PNG encoder's best compression, indexed when it has at
/// most 256 colours (a plot usually has: flat colours, lines and anti-aliased text), so that the
/// figures committed under docs/ stay small.
fn write_png(out: &Path, (w, h): (u32, u32), rgb: &[u8]) -> Result<(), String> {
    let mut palette: Vec<[u8; 3]> = Vec::new();
    let mut index = std::collections::HashMap::new();
    let mut indexed = Vec::with_capacity(rgb.len() / 3);
    for px in rgb.chunks_exact(3) {
        let c = [px[0], px[1], px[2]];
        let i = *index.entry(c).or_insert_with(|| {
            palette.push(c);
            palette.len() - 1
        });
        if palette.len() > 256 {
            break;
        }
        indexed.push(i as u8);
    }
    let mut bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut bytes, w, h);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Best);
        encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
        let data: &[u8] = if palette.len() <= 256 {
            encoder.set_color(png::ColorType::Indexed);
            encoder.set_palette(palette.concat());
            &indexed
        } else {
            encoder.set_color(png::ColorType::Rgb);
            rgb
        };
        let mut writer = encoder
            .write_header()
            .map_err(|e| format!("{}: {e}", out.display()))?;
        writer
            .write_image_data(data)
            .map_err(|e| format!("{}: {e}", out.display()))?;
        writer
            .finish()
            .map_err(|e| format!("{}: {e}", out.display()))?;
    }
    // Whole or not at all: a figure is never left half-written.
    agents::ppo::store::write_atomic(out, &bytes)
}

/// The palette, one colour per run.
const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Draws reward, hit rate and success rate against control steps for every series into `out`.
pub fn learning_curves(series: &[Series], out: &Path) -> Result<(), String> {
    font()?;
    draw_png(out, (1500, 450), |root| {
        let panels = root.split_evenly((1, 3));
        let max_steps = series
            .iter()
            .flat_map(|s| s.rows.iter().map(|r| r.env_steps))
            .max()
            .unwrap_or(1)
            .max(1) as f64;
        type Pick = fn(&CurveRow) -> f64;
        let metrics: [(&str, Pick); 3] = [
            ("mean episode reward", |r| r.reward),
            ("hit rate (training)", |r| r.hit_rate),
            ("success rate (training)", |r| r.success_rate),
        ];
        for (panel, (title, pick)) in panels.iter().zip(metrics) {
            let values = series
                .iter()
                .flat_map(|s| s.rows.iter().filter(|r| r.episodes > 0).map(pick));
            let (lo, hi) = if title.starts_with("mean") {
                let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    (a.min(v), b.max(v))
                });
                if lo.is_finite() && hi > lo {
                    (lo.min(0.0), hi * 1.05)
                } else {
                    (0.0, 1.0)
                }
            } else {
                (0.0, 1.0)
            };
            let mut chart = steps_chart(panel, (title, 20), max_steps, lo..hi)?;
            for (k, s) in series.iter().enumerate() {
                let colour = COLOURS[k % COLOURS.len()];
                chart
                    .draw_series(LineSeries::new(
                        // Rows before the first finished episode have no statistics yet.
                        s.rows
                            .iter()
                            .filter(|r| r.episodes > 0)
                            .map(|r| (r.env_steps as f64 / 1e6, pick(r))),
                        colour.stroke_width(2),
                    ))
                    .map_err(|e| e.to_string())?
                    .label(s.label.clone())
                    .legend(legend_line(colour));
            }
            draw_legend(&mut chart, SeriesLabelPosition::LowerRight)?;
        }
        Ok(())
    })
}

/// A panel's chart against control steps (millions): its caption (text, size), the steps' range up
/// to `max_steps`, `y`, and the mesh.
fn steps_chart<'a, 'b>(
    panel: &'a DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>,
    caption: (&str, u32),
    max_steps: f64,
    y: std::ops::Range<f64>,
) -> Result<StepsChart<'a, 'b>, String> {
    let mut chart = ChartBuilder::on(panel)
        .caption(caption.0, ("sans-serif", caption.1))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(52)
        .build_cartesian_2d(0.0..max_steps / 1e6, y)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("control steps (millions)")
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(|e| e.to_string())?;
    Ok(chart)
}

type StepsChart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<Coord, Coord>>;
type Coord = plotters::coord::types::RangedCoordf64;

/// A legend entry's short line in `colour`.
fn legend_line(colour: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
}

/// The legend box of a chart's labelled series, at `position`.
fn draw_legend<'a, 'b: 'a>(
    chart: &mut StepsChart<'a, 'b>,
    position: SeriesLabelPosition,
) -> Result<(), String> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .position(position)
        .draw()
        .map_err(|e| e.to_string())
}

/// One variant's learning curves, one per seed: (env steps, hit rate, success rate) points.
pub struct SeedCurves {
    /// Legend label.
    pub label: String,
    /// Each seed's curve.
    pub seeds: Vec<Vec<(f64, f64, f64)>>,
}

/// Bins each seed's curve on a common grid of `bins` intervals up to `max_steps` and returns, for
/// every bin that every seed has a point in, (the bin's centre, mean, std over seeds) of `pick`.
fn seed_band(
    seeds: &[Vec<(f64, f64, f64)>],
    max_steps: f64,
    bins: usize,
    pick: fn(&(f64, f64, f64)) -> f64,
) -> Vec<(f64, f64, f64)> {
    let width = max_steps / bins as f64;
    (0..bins)
        .filter_map(|b| {
            let (lo, hi) = (b as f64 * width, (b + 1) as f64 * width);
            let per_seed: Option<Vec<f64>> = seeds
                .iter()
                .map(|c| {
                    let inside: Vec<f64> = c
                        .iter()
                        .filter(|p| p.0 > lo && p.0 <= hi)
                        .map(pick)
                        .collect();
                    (!inside.is_empty()).then(|| inside.iter().sum::<f64>() / inside.len() as f64)
                })
                .collect();
            let v = per_seed?;
            let n = v.len() as f64;
            let mean = v.iter().sum::<f64>() / n;
            let var = if v.len() > 1 {
                v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0)
            } else {
                0.0
            };
            Some((0.5 * (lo + hi), mean, var.sqrt()))
        })
        .collect()
}

/// Draws hit and success rate against control steps for every variant into `out`: the mean over
/// its seeds as a line, ± one standard deviation as a band.
pub fn ablation_curves(variants: &[SeedCurves], out: &Path) -> Result<(), String> {
    font()?;
    draw_png(out, (1200, 450), |root| {
        let panels = root.split_evenly((1, 2));
        let max_steps = variants
            .iter()
            .flat_map(|v| v.seeds.iter().flatten().map(|p| p.0))
            .fold(1.0, f64::max);
        type Pick = fn(&(f64, f64, f64)) -> f64;
        let metrics: [(&str, Pick); 2] = [
            ("hit rate (training), mean ± std over seeds", |p| p.1),
            ("success rate (training), mean ± std over seeds", |p| p.2),
        ];
        for (panel, (title, pick)) in panels.iter().zip(metrics) {
            let mut chart = steps_chart(panel, (title, 18), max_steps, 0.0..1.0)?;
            for (k, v) in variants.iter().enumerate() {
                let colour = COLOURS[k % COLOURS.len()];
                let band = seed_band(&v.seeds, max_steps, 60, pick);
                if band.is_empty() {
                    continue;
                }
                let mut outline: Vec<(f64, f64)> = band
                    .iter()
                    .map(|&(x, m, sd)| (x / 1e6, (m + sd).min(1.0)))
                    .collect();
                outline.extend(
                    band.iter()
                        .rev()
                        .map(|&(x, m, sd)| (x / 1e6, (m - sd).max(0.0))),
                );
                chart
                    .draw_series(std::iter::once(Polygon::new(outline, colour.mix(0.2))))
                    .map_err(|e| e.to_string())?;
                chart
                    .draw_series(LineSeries::new(
                        band.iter().map(|&(x, m, _)| (x / 1e6, m)),
                        colour.stroke_width(2),
                    ))
                    .map_err(|e| e.to_string())?
                    .label(v.label.clone())
                    .legend(legend_line(colour));
            }
            draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        }
        Ok(())
    })
}

/// Draws the distribution of rally lengths of each series (fraction of rallies with each number of
/// returns, lengths above `max_len` in the last bin) into `out`.
pub fn rally_histogram(
    series: &[(String, Vec<u32>)],
    max_len: u32,
    out: &Path,
) -> Result<(), String> {
    font()?;
    draw_png(out, (900, 450), |root| {
        let bins = max_len as usize + 1;
        let fractions: Vec<Vec<f64>> = series
            .iter()
            .map(|(_, lengths)| {
                let mut h = vec![0.0; bins];
                for &l in lengths {
                    h[(l as usize).min(bins - 1)] += 1.0 / lengths.len().max(1) as f64;
                }
                h
            })
            .collect();
        let top = fractions
            .iter()
            .flatten()
            .fold(0.0f64, |a, &b| a.max(b))
            .max(0.05)
            * 1.1;
        let mut chart = ChartBuilder::on(root)
            .caption("rally length (legal returns per rally)", ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(52)
            .build_cartesian_2d(-0.5..bins as f64 - 0.5, 0.0..top)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc(format!("returns ({max_len}: {max_len} or more)"))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_desc("fraction of rallies")
            .label_style(("sans-serif", 13))
            .draw()
            .map_err(|e| e.to_string())?;
        let width = 0.8 / series.len().max(1) as f64;
        for (k, ((label, _), h)) in series.iter().zip(&fractions).enumerate() {
            let colour = COLOURS[k % COLOURS.len()];
            let x0 = -0.4 + k as f64 * width;
            chart
                .draw_series(h.iter().enumerate().map(|(i, &f)| {
                    let x = i as f64 + x0;
                    Rectangle::new([(x, 0.0), (x + width, f)], colour.filled())
                }))
                .map_err(|e| e.to_string())?
                .label(label.clone())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 12, y + 5)], colour.filled())
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 13))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| e.to_string())?;
        Ok(())
    })
}

/// One panel of the return-distribution figure: the serves' and the returns' crossings `(y_r, z)`
/// of the receiver's hitting plane.
pub struct Crossings {
    /// Panel title.
    pub title: String,
    /// Serves (exchange 0).
    pub serves: Vec<(f64, f64)>,
    /// Returns (exchange ≥ 1).
    pub returns: Vec<(f64, f64)>,
}

/// Draws the paper's return-distribution figure: per panel, the serves and the returns where they
/// cross the receiver's hitting plane, with the serve box.
pub fn return_distribution(panels: &[Crossings], out: &Path) -> Result<(), String> {
    font()?;
    let n = panels.len().max(1);
    draw_png(out, (450 * n as u32, 450), |root| {
        let (bz0, bz1) = sim::arena::SERVE_BOX_Z;
        let by = sim::arena::SERVE_BOX_HALF_WIDTH;
        for (area, p) in root.split_evenly((1, n)).iter().zip(panels) {
            let mut chart = ChartBuilder::on(area)
                .caption(&p.title, ("sans-serif", 17))
                .margin(12)
                .x_label_area_size(36)
                .y_label_area_size(46)
                .build_cartesian_2d(-1.5..1.5, 0.6..1.9)
                .map_err(|e| e.to_string())?;
            chart
                .configure_mesh()
                .x_desc("y at the hitting plane, receiver's frame (m)")
                .y_desc("z (m)")
                .label_style(("sans-serif", 12))
                .draw()
                .map_err(|e| e.to_string())?;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(-by, bz0), (by, bz1)],
                    BLACK.stroke_width(2),
                )))
                .map_err(|e| e.to_string())?
                .label("serve box")
                .legend(|(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 12, y + 5)], BLACK.stroke_width(2))
                });
            for (pts, label, colour) in [
                (&p.serves, "serves", COLOURS[0]),
                (&p.returns, "returns", COLOURS[1]),
            ] {
                chart
                    .draw_series(
                        pts.iter()
                            .map(|&(y, z)| Circle::new((y, z), 2, colour.mix(0.6).filled())),
                    )
                    .map_err(|e| e.to_string())?
                    .label(format!("{label} ({})", pts.len()))
                    .legend(move |(x, y)| Circle::new((x + 6, y), 4, colour.filled()));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font(("sans-serif", 12))
                .position(SeriesLabelPosition::UpperLeft)
                .draw()
                .map_err(|e| e.to_string())?;
        }
        Ok(())
    })
}

/// Arguments of `rally plot`.
#[derive(Args, Debug)]
#[command(
    after_help = "Example:\n  rally plot runs/kmac runs/muscle runs/muscle-pd runs/dynsyn --out docs/curves.png\n\n\
                  Text is set in DejaVu Sans, built in; RALLY_FONT=FILE sets it in another TrueType font."
)]
pub struct PlotArgs {
    /// Training run directories (each with a curve.csv) or curve CSV files, one line each: labelled
    /// by the directory, and by the file's name too when it is not curve.csv.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// The PNG to write.
    #[arg(long, default_value = "curves.png")]
    out: PathBuf,
}

/// Runs `rally plot`.
pub fn run(args: &PlotArgs) -> Result<(), CliError> {
    let mut series = Vec::new();
    for r in &args.runs {
        let csv = if r.is_dir() {
            r.join("curve.csv")
        } else {
            r.clone()
        };
        let rows = read_curve(&csv).map_err(CliError::Usage)?;
        // A run directory, or a file named curve.csv, is labelled by the run's directory; another
        // CSV by its directory and name (two curves of one directory must not share a label).
        let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().to_string());
        let dir = if r.is_dir() {
            Some(r.as_path())
        } else {
            r.parent()
        };
        let run = dir.and_then(name);
        let stem = csv.file_stem().map(|s| s.to_string_lossy().to_string());
        let label = match (run, stem) {
            (Some(run), Some(stem)) if !r.is_dir() && stem != "curve" => format!("{run}/{stem}"),
            (Some(run), _) => run,
            (None, _) => csv.display().to_string(),
        };
        series.push(Series { label, rows });
    }
    learning_curves(&series, &args.out).map_err(|e| CliError::Failed(anyhow!(e)))?;
    println!("{}", args.out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::write_png;

    /// Decodes a PNG to 8-bit RGB, palettes expanded.
    fn decode(path: &std::path::Path) -> (png::ColorType, Vec<u8>) {
        let mut decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
        decoder.set_transformations(png::Transformations::EXPAND);
        let mut reader = decoder.read_info().unwrap();
        let stored = reader.info().color_type;
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        buf.truncate(info.buffer_size());
        (stored, buf)
    }

    #[test]
    fn png_is_lossless_indexed_up_to_256_colours_and_rgb_beyond() {
        let dir = std::env::temp_dir().join(format!("rally-png-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (w, h) = (40u32, 30u32);
        for colours in [3usize, 256, 257, 1200] {
            let rgb: Vec<u8> = (0..(w * h) as usize)
                .flat_map(|i| {
                    let c = (i * 7919) % colours;
                    [(c % 256) as u8, (c / 256) as u8, 17]
                })
                .collect();
            let path = dir.join(format!("{colours}.png"));
            write_png(&path, (w, h), &rgb).unwrap();
            let (stored, back) = decode(&path);
            assert_eq!(back, rgb, "{colours} colours");
            let want = if colours <= 256 {
                png::ColorType::Indexed
            } else {
                png::ColorType::Rgb
            };
            assert_eq!(stored, want, "{colours} colours");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
