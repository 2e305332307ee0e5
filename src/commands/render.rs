//! `looming render`: one scan pair of a log as a PNG, so the paper's figures
//! can be made again without a viewer: the colourised range image of a
//! channel (`--view range`) or a top view of the coloured cloud
//! (`--view top`), with the threat zones for the threat channel.
//!
//! The log is replayed like `eval` does (auto-detected topics, raw or
//! annotated logs alike); the engine runs, with `RenderOptions::engine` (the
//! defaults from the command line), only on the chosen pair. Colours are [`crate::annotate::colour`]'s, as in the
//! annotated output.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use image::{ImageEncoder, Rgb, RgbImage};

use crate::annotate::colour;
use crate::engine::{self, EngineConfig, NO_POINT, PairLooming};
use crate::input::{InputError, InputFile};
use crate::model::ScanPair;
use crate::output::{AtomicFile, same_file};
use crate::pipeline::{ReplayError, ScanOptions, replay_input};

/// What a pixel shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RenderChannel {
    /// Fused looming of the cell, grey where masked.
    Fused,
    /// LiDAR-only looming of the cell wherever computed, masked cells
    /// included (the paper's LiDAR-only figure, edge effects and all).
    Lidar,
    /// `L_ego` of the cell's point (the paper's LiDAR + IMU figure); grey
    /// without a velocity.
    Ego,
    /// `D = L_lidar - L_ray_ego`, grey where masked.
    Disagreement,
    /// Threat level of the cell, grey where masked.
    Threat,
}

/// How the scan is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RenderView {
    /// The range image: a row of cells per beam (highest at the top), forward
    /// at the centre column, the vehicle's left on the image's left.
    Range,
    /// The cloud seen from above: x (forward) up, y (left) left, the sensor at
    /// the centre.
    Top,
}

/// Which scan pair to render.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RenderAt {
    /// Seconds after the log's first message log time: the first pair whose
    /// current scan was logged at or after that time.
    Time(f64),
    /// 0-based index of the scan pair (as `/looming/pairs` numbers them).
    Frame(u64),
    /// A log time, ns: the first pair whose current scan was logged at or
    /// after it (an event's `peak.log_time_ns` names its peak pair).
    LogTimeNs(u64),
}

#[derive(Debug, Clone)]
pub struct RenderOptions {
    pub input: PathBuf,
    pub output: PathBuf,
    pub channel: RenderChannel,
    pub at: RenderAt,
    pub view: RenderView,
    /// Range view: pixel rows per beam (at least 1).
    pub row_height_px: u32,
    /// Top view: metres from the sensor (centre) to the image's edge.
    pub top_extent_m: f64,
    /// Top view: width and height, pixels (at least 1).
    pub top_size_px: u32,
    /// Replace an existing output.
    pub force: bool,
    /// How the log is read, decoded and paired (as `process` would).
    pub scans: ScanOptions,
    /// The engine's settings (`batch` passes those of its `process` run).
    pub engine: EngineConfig,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            input: PathBuf::new(),
            output: PathBuf::new(),
            channel: RenderChannel::Fused,
            at: RenderAt::Frame(0),
            view: RenderView::Range,
            row_height_px: 4,
            top_extent_m: 40.0,
            top_size_px: 800,
            force: false,
            scans: ScanOptions::default(),
            engine: EngineConfig::default(),
        }
    }
}

/// What was rendered.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RenderSummary {
    pub pair_index: u64,
    /// Header stamp of the pair's current scan, ns.
    pub stamp_ns: i64,
    /// Log time of the pair's current scan, ns.
    pub log_time_ns: u64,
    pub width_px: u32,
    pub height_px: u32,
    pub output: PathBuf,
}

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Input(#[from] InputError),
    #[error(transparent)]
    Replay(#[from] ReplayError),
    #[error("{path}: no scan pair at {at} (the log has {pairs} pairs)")]
    NotFound {
        path: PathBuf,
        at: String,
        pairs: u64,
    },
    #[error("the time must be a finite number of seconds, not {0}")]
    BadTime(f64),
    #[error("{path}: pair {pair_index} gives no range image (too few points or no beam structure)")]
    NoImage { path: PathBuf, pair_index: u64 },
    #[error("{path}: the output must not be the input file")]
    SameAsInput { path: PathBuf },
    #[error("{path}: exists already")]
    Exists { path: PathBuf },
    #[error("{path}: cannot write the PNG: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot encode the PNG: {source}")]
    Encode {
        path: PathBuf,
        source: image::ImageError,
    },
}

impl RenderError {
    /// `strict` and the log had a bad message or was truncated (exit code 3
    /// by the CLI's convention, as for `process`).
    pub fn is_strict(&self) -> bool {
        matches!(self, RenderError::Replay(ReplayError::Strict(_)))
    }

    /// A usage error (exit code 2 by the CLI's convention): a bad argument, a
    /// pair that does not exist, an unusable topic choice, an output that
    /// exists or is the input.
    pub fn is_usage(&self) -> bool {
        matches!(
            self,
            RenderError::NotFound { .. }
                | RenderError::BadTime(_)
                | RenderError::SameAsInput { .. }
                | RenderError::Exists { .. }
                | RenderError::Replay(ReplayError::Topic { .. })
        )
    }
}

/// Replay `options.input`, run the engine on the chosen pair and write its
/// image to `options.output` (a temporary file beside it, renamed when
/// complete).
pub fn render(options: &RenderOptions) -> Result<RenderSummary, RenderError> {
    let picture = Picture {
        at: options.at,
        channel: options.channel,
        view: options.view,
        output: options.output.clone(),
    };
    let mut summaries = render_pictures(options, std::slice::from_ref(&picture))?;
    Ok(summaries.remove(0))
}

/// One image [`render_pictures`] makes: which pair, what it shows, where it
/// goes.
#[derive(Debug, Clone)]
pub struct Picture {
    pub at: RenderAt,
    pub channel: RenderChannel,
    pub view: RenderView,
    pub output: PathBuf,
}

/// Several images of one log from a single replay (the engine runs once per
/// pair pictured): what `batch` draws for each near miss. The input, scan
/// options, sizes and `force` come from `options`; its `at`, `channel`,
/// `view` and `output` are not used. The summaries come in `pictures`' order.
pub fn render_pictures(
    options: &RenderOptions,
    pictures: &[Picture],
) -> Result<Vec<RenderSummary>, RenderError> {
    for picture in pictures {
        check_picture(options, picture)?;
    }
    let input = InputFile::open(&options.input, options.scans.input_options.clone())?;
    let start_ns = input.catalog().start_ns;
    let wanted: Vec<Wanted> = pictures
        .iter()
        .map(|p| Wanted::new(p.at, start_ns))
        .collect();
    // Each picture's pair, as an index into `pairs` (a pair two pictures
    // share is kept once).
    let mut chosen: Vec<Option<usize>> = vec![None; pictures.len()];
    let mut pairs: Vec<ScanPair> = Vec::new();
    let mut seen = 0u64;
    // The callback API reads the whole log; pairs after the chosen ones are
    // only counted.
    replay_input(&input, &options.scans, &mut |_| {}, &mut |pair| {
        seen += 1;
        let mut kept = None;
        for (slot, want) in chosen.iter_mut().zip(&wanted) {
            if slot.is_none() && want.matches(&pair) {
                *slot = Some(*kept.get_or_insert(pairs.len()));
            }
        }
        if kept.is_some() {
            pairs.push(pair);
        }
    })?;
    let mut computed: Vec<Option<PairLooming>> = vec![None; pairs.len()];
    let mut summaries = Vec::with_capacity(pictures.len());
    for ((picture, want), slot) in pictures.iter().zip(&wanted).zip(&chosen) {
        let Some(index) = *slot else {
            return Err(RenderError::NotFound {
                path: options.input.clone(),
                at: want.describe(),
                pairs: seen,
            });
        };
        let pair = &pairs[index];
        if computed[index].is_none() {
            computed[index] = engine::compute(pair, &options.engine);
        }
        let looming = computed[index]
            .as_ref()
            .ok_or_else(|| RenderError::NoImage {
                path: options.input.clone(),
                pair_index: pair.index,
            })?;
        summaries.push(draw(options, picture, pair, looming)?);
    }
    Ok(summaries)
}

/// A picture's request, checked before the log is read.
fn check_picture(options: &RenderOptions, picture: &Picture) -> Result<(), RenderError> {
    if let RenderAt::Time(t) = picture.at
        && !t.is_finite()
    {
        return Err(RenderError::BadTime(t));
    }
    if same_file(&options.input, &picture.output) {
        return Err(RenderError::SameAsInput {
            path: picture.output.clone(),
        });
    }
    if !options.force && picture.output.exists() {
        return Err(RenderError::Exists {
            path: picture.output.clone(),
        });
    }
    Ok(())
}

/// Draw one picture of its pair and write it.
fn draw(
    options: &RenderOptions,
    picture: &Picture,
    pair: &ScanPair,
    looming: &PairLooming,
) -> Result<RenderSummary, RenderError> {
    let image = render_image(pair, looming, picture.channel, picture.view, options);
    write_png(&image, &picture.output, options.force)?;
    Ok(RenderSummary {
        pair_index: pair.index,
        stamp_ns: pair.current.stamp_ns,
        log_time_ns: pair.current_log_time_ns,
        width_px: image.width(),
        height_px: image.height(),
        output: picture.output.clone(),
    })
}

/// The pair asked for, resolved against the log's start.
enum Wanted {
    Frame(u64),
    /// Seconds asked for and the log time they give (None: empty log).
    Time(f64, Option<u64>),
    LogTime(u64),
}

impl Wanted {
    fn new(at: RenderAt, start_ns: Option<u64>) -> Self {
        match at {
            RenderAt::Frame(index) => Wanted::Frame(index),
            RenderAt::LogTimeNs(target) => Wanted::LogTime(target),
            RenderAt::Time(t) => Wanted::Time(
                t,
                start_ns.map(|start| {
                    let target = start as f64 + (t * 1e9).round();
                    target.clamp(0.0, u64::MAX as f64) as u64
                }),
            ),
        }
    }

    fn matches(&self, pair: &ScanPair) -> bool {
        match *self {
            Wanted::Frame(index) => pair.index == index,
            Wanted::Time(_, target) => target.is_some_and(|t| pair.current_log_time_ns >= t),
            Wanted::LogTime(target) => pair.current_log_time_ns >= target,
        }
    }

    fn describe(&self) -> String {
        match *self {
            Wanted::Frame(index) => format!("frame {index}"),
            Wanted::Time(t, Some(target)) => format!("time {t} s (log time {target} ns)"),
            Wanted::Time(t, None) => format!("time {t} s"),
            Wanted::LogTime(target) => format!("log time {target} ns"),
        }
    }
}

/// The image of one pair (pure): the range image or the top view of
/// `channel`. Sizes from `options` (`row_height_px`, `top_extent_m`,
/// `top_size_px`; the paths, `at` and `force` are not used).
pub(crate) fn render_image(
    pair: &ScanPair,
    looming: &PairLooming,
    channel: RenderChannel,
    view: RenderView,
    options: &RenderOptions,
) -> RgbImage {
    match view {
        RenderView::Range => range_view(looming, channel, options.row_height_px.max(1)),
        RenderView::Top => top_view(
            pair,
            looming,
            channel,
            options.top_size_px.max(1),
            options.top_extent_m,
        ),
    }
}

fn rgb(c: colour::Rgba) -> Rgb<u8> {
    Rgb([c[0], c[1], c[2]])
}

/// Colour of an occupied cell (or of an empty one: [`colour::EMPTY`]).
fn cell_colour(looming: &PairLooming, channel: RenderChannel, cell: usize) -> colour::Rgba {
    let point = looming.image.point[cell];
    if point == NO_POINT {
        return colour::EMPTY;
    }
    let masked = looming.mask[cell] != 0;
    match channel {
        RenderChannel::Fused if masked => colour::MASKED,
        RenderChannel::Fused => colour::looming(looming.fused[cell]),
        RenderChannel::Lidar => colour::looming(looming.l_lidar[cell]),
        RenderChannel::Ego => colour::looming(looming.l_ego[point as usize]),
        RenderChannel::Disagreement if masked => colour::MASKED,
        RenderChannel::Disagreement => colour::looming(looming.disagreement[cell]),
        RenderChannel::Threat if masked => colour::MASKED,
        RenderChannel::Threat => colour::threat(looming.threat[cell]),
    }
}

/// `row_height_px` pixel rows per beam, highest beam at the top; columns as
/// the engine's (forward at the centre, the left on the left), as in
/// `annotate::foxglove::range_image`.
fn range_view(looming: &PairLooming, channel: RenderChannel, row_height_px: u32) -> RgbImage {
    let (rows, cols) = (looming.geometry.rows, looming.geometry.cols);
    let height = rows as u32 * row_height_px;
    RgbImage::from_fn(cols as u32, height, |x, y| {
        let row = rows - 1 - (y / row_height_px) as usize;
        rgb(cell_colour(looming, channel, row * cols + x as usize))
    })
}

/// Side of the square drawn per point, pixels.
const POINT_PX: i64 = 2;
/// Half side of the sensor's white marker, pixels (a 5 x 5 square).
const MARKER_HALF_PX: i64 = 2;
const WHITE: Rgb<u8> = Rgb([255, 255, 255]);

/// Top view: every point of the current scan, lowest first so that the
/// highest point of a column of the world wins its pixels; for the threat
/// channel the sections of the equal-looming spheres by the plane z = 0 on
/// top; the sensor's marker last.
fn top_view(
    pair: &ScanPair,
    looming: &PairLooming,
    channel: RenderChannel,
    size_px: u32,
    extent_m: f64,
) -> RgbImage {
    let scan = &*pair.current;
    let mut image = RgbImage::from_pixel(size_px, size_px, rgb(colour::EMPTY));
    let projection = TopProjection::new(size_px, extent_m);
    let mut order: Vec<usize> = (0..scan.points_m.len()).collect();
    order.sort_by(|&a, &b| scan.points_m[a][2].total_cmp(&scan.points_m[b][2]));
    for index in order {
        let p = scan.points_m[index];
        let c = match channel {
            RenderChannel::Ego => colour::looming(looming.l_ego[index]),
            _ => looming
                .image
                .surface_cell(index)
                .map_or(colour::MASKED, |cell| cell_colour(looming, channel, cell)),
        };
        let (u, v) = projection.pixel_f(f64::from(p[0]), f64::from(p[1]));
        // The 2 x 2 block whose centre is nearest the point.
        let (u0, v0) = ((u - 0.5).floor() as i64, (v - 0.5).floor() as i64);
        fill(&mut image, u0, v0, POINT_PX, rgb(c));
    }
    if channel == RenderChannel::Threat
        && let Some(spheres) = &looming.spheres
    {
        for sphere in spheres {
            let [cx, cy, cz] = sphere.center_m;
            let r = sphere.radius_m;
            if cz.abs() < r {
                let radius_m = (r * r - cz * cz).sqrt();
                circle(
                    &mut image,
                    &projection,
                    (cx, cy),
                    radius_m,
                    rgb(colour::threat(sphere.level)),
                );
            }
        }
    }
    let centre = i64::from(size_px / 2);
    fill(
        &mut image,
        centre - MARKER_HALF_PX,
        centre - MARKER_HALF_PX,
        2 * MARKER_HALF_PX + 1,
        WHITE,
    );
    image
}

/// LiDAR-frame (x, y) to continuous pixel coordinates of the top view.
struct TopProjection {
    half_px: f64,
    px_per_m: f64,
}

impl TopProjection {
    fn new(size_px: u32, extent_m: f64) -> Self {
        let half_px = f64::from(size_px) / 2.0;
        Self {
            half_px,
            px_per_m: half_px / extent_m,
        }
    }

    /// (column, row): x forward is up, y left is left.
    fn pixel_f(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        (
            self.half_px - y_m * self.px_per_m,
            self.half_px - x_m * self.px_per_m,
        )
    }
}

fn put(image: &mut RgbImage, u: i64, v: i64, c: Rgb<u8>) {
    if (0..i64::from(image.width())).contains(&u) && (0..i64::from(image.height())).contains(&v) {
        image.put_pixel(u as u32, v as u32, c);
    }
}

fn fill(image: &mut RgbImage, u0: i64, v0: i64, side: i64, c: Rgb<u8>) {
    for v in v0..v0 + side {
        for u in u0..u0 + side {
            put(image, u, v, c);
        }
    }
}

/// A 1-pixel outline: the pixels under points of the circle at least two per
/// pixel of circumference apart, angles from the +x axis (a multiple of 8 of
/// them, so the four axis points are drawn exactly).
fn circle(
    image: &mut RgbImage,
    projection: &TopProjection,
    (cx, cy): (f64, f64),
    radius_m: f64,
    c: Rgb<u8>,
) {
    let circumference_px = std::f64::consts::TAU * radius_m * projection.px_per_m;
    if !circumference_px.is_finite() {
        return;
    }
    let steps = ((2.0 * circumference_px / 8.0).ceil().clamp(8.0, 1e6) as usize) * 8;
    for k in 0..steps {
        let angle = std::f64::consts::TAU * k as f64 / steps as f64;
        let (u, v) = projection.pixel_f(cx + radius_m * angle.cos(), cy + radius_m * angle.sin());
        put(image, u.floor() as i64, v.floor() as i64, c);
    }
}

/// Encode to a temporary file beside `path` and rename it into place; without
/// `force` an output that appeared meanwhile is not replaced.
fn write_png(image: &RgbImage, path: &Path, force: bool) -> Result<(), RenderError> {
    let io_err = |source| RenderError::Write {
        path: path.to_path_buf(),
        source,
    };
    let mut writer = BufWriter::new(AtomicFile::create(path).map_err(io_err)?);
    image::codecs::png::PngEncoder::new(&mut writer)
        .write_image(
            image.as_raw(),
            image.width(),
            image.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|source| RenderError::Encode {
            path: path.to_path_buf(),
            source,
        })?;
    writer.flush().map_err(io_err)?;
    let file = writer.into_inner().map_err(|e| io_err(e.into_error()))?;
    let committed = if force {
        file.commit()
    } else {
        file.commit_no_clobber()
    };
    committed.map_err(|error| {
        if !force && error.kind() == std::io::ErrorKind::AlreadyExists {
            RenderError::Exists {
                path: path.to_path_buf(),
            }
        } else {
            io_err(error)
        }
    })?;
    Ok(())
}
