//! Convergence plots of an ADMM run from its residual checks ([`History`]): the relative
//! primal and dual residuals on a log10 axis (top panel) and the energy Σ w E(A) with the
//! energies of recovered maps as dots (bottom panel), against the iteration.
//!
//! The figure is laid out once as a list of primitives in pixels; [`convergence_svg`] and
//! [`convergence_png`] only translate the primitives, so both pictures show the same thing.
#![forbid(unsafe_code)]

use std::fmt::Write;
use std::io;

use super::raster::Canvas;
use crate::param::admm::History;

/// A residual series: how to read it from a check, and its colour.
type Series = (fn(&History) -> f64, [u8; 3]);

/// Size of the SVG plot in px.
const SVG_SIZE: (u32, u32) = (960, 640);

const PRIMAL: [u8; 3] = [31, 119, 180];
const DUAL: [u8; 3] = [255, 127, 14];
const ENERGY: [u8; 3] = [44, 160, 44];
const RECOVERED: [u8; 3] = [148, 103, 189];
const AXIS: [u8; 3] = [60, 60, 60];
const GRID: [u8; 3] = [228, 228, 228];
const INK: [u8; 3] = [40, 40, 40];
const BG: [u8; 3] = [255, 255, 255];

#[derive(Clone, Copy, Debug, PartialEq)]
enum Anchor {
    Start,
    Middle,
    End,
}

/// A drawing primitive in px (y down).
#[derive(Clone, Debug, PartialEq)]
enum Prim {
    Rect {
        x: f64,
        y: f64,
        w: f64,
        h: f64,
        color: [u8; 3],
    },
    Line {
        pts: Vec<[f64; 2]>,
        width: f64,
        color: [u8; 3],
    },
    Dot {
        x: f64,
        y: f64,
        r: f64,
        color: [u8; 3],
    },
    /// `y` is the top of the 5×7 glyph cell; `scale` px per font pixel.
    Text {
        x: f64,
        y: f64,
        text: String,
        scale: usize,
        anchor: Anchor,
        color: [u8; 3],
    },
}

struct Figure {
    w: u32,
    h: u32,
    prims: Vec<Prim>,
}

/// One panel: its rectangle in px and its data range.
struct Panel {
    x: f64,
    y: f64,
    w: f64,
    h: f64,
    x_range: (f64, f64),
    y_range: (f64, f64),
}

impl Panel {
    fn map(&self, x: f64, y: f64) -> [f64; 2] {
        let (x0, x1) = self.x_range;
        let (y0, y1) = self.y_range;
        [
            self.x + (x - x0) / (x1 - x0) * self.w,
            self.y + self.h - (y - y0) / (y1 - y0) * self.h,
        ]
    }
}

/// A 1-2-5 step giving about `target` intervals over `range`.
fn nice_step(range: f64, target: f64) -> f64 {
    let raw = (range / target).max(f64::MIN_POSITIVE);
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let nf = if f < 1.5 {
        1.0
    } else if f < 3.0 {
        2.0
    } else if f < 7.0 {
        5.0
    } else {
        10.0
    };
    nf * mag
}

/// Multiples of `step` inside [lo, hi].
fn ticks(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let (a, b) = (
        (lo / step - 1e-9).ceil() as i64,
        (hi / step + 1e-9).floor() as i64,
    );
    (a..=b).map(|k| k as f64 * step).collect()
}

/// Tick label of a linear axis with tick spacing `step`.
fn linear_label(v: f64, step: f64) -> String {
    if v.abs() >= 1e6 || (v != 0.0 && v.abs() < 1e-4) {
        return format!("{v:.2e}");
    }
    let decimals = (-(step.log10() + 1e-9).floor()).clamp(0.0, 10.0) as usize;
    let s = format!("{v:.decimals$}");
    if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
        s[1..].to_string()
    } else {
        s
    }
}

/// Tick label of a log10 axis at decade `e`.
fn decade_label(e: i32) -> String {
    if e == 0 {
        "1".into()
    } else {
        format!("1e{e}")
    }
}

/// Runs of consecutive points with a value (a missing value breaks the line).
fn runs(points: impl Iterator<Item = Option<[f64; 2]>>) -> Vec<Vec<[f64; 2]>> {
    let mut out: Vec<Vec<[f64; 2]>> = vec![Vec::new()];
    for p in points {
        match p {
            Some(p) => {
                if let Some(r) = out.last_mut() {
                    r.push(p);
                }
            }
            None => {
                if out.last().is_some_and(|r| !r.is_empty()) {
                    out.push(Vec::new());
                }
            }
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

fn positive_log(x: f64) -> Option<f64> {
    (x > 0.0 && x.is_finite()).then(|| x.log10())
}

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

/// Lays out the two-panel figure in a `w`×`h` px picture.
fn figure(history: &[History], w: u32, h: u32) -> Figure {
    let (wf, hf) = (w.max(1) as f64, h.max(1) as f64);
    let s = (hf.min(0.75 * wf) / 300.0).floor().max(1.0) as usize;
    let sc = s as f64;
    let (cw, ch) = (6.0 * sc, 7.0 * sc);
    let line_w = sc + 0.5;
    let thin = (0.5 * sc).round().max(1.0);
    let mut prims = Vec::new();

    // Data ranges.
    let it_max = history
        .iter()
        .map(|h| h.iteration)
        .max()
        .unwrap_or(0)
        .max(1) as f64;
    let x_range = (0.0, it_max);
    let x_step = nice_step(it_max, 6.0).max(1.0);

    let logs: Vec<f64> = history
        .iter()
        .flat_map(|h| [positive_log(h.primal), positive_log(h.dual)])
        .flatten()
        .collect();
    let (mut rlo, mut rhi) = logs.iter().fold((i32::MAX, i32::MIN), |(lo, hi), &l| {
        (lo.min(l.floor() as i32), hi.max(l.ceil() as i32))
    });
    if logs.is_empty() {
        (rlo, rhi) = (-6, 0);
    }
    if rhi <= rlo {
        rhi = rlo + 1;
    }
    let r_every = ((rhi - rlo) as f64 / 6.0).ceil().max(1.0) as i32;
    let r_ticks: Vec<i32> = (rlo..=rhi).filter(|e| (e - rlo) % r_every == 0).collect();

    let energies: Vec<f64> = history
        .iter()
        .flat_map(|h| [finite(h.energy), h.recovered_energy.and_then(finite)])
        .flatten()
        .collect();
    let (mut elo, mut ehi) = energies
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &e| {
            (lo.min(e), hi.max(e))
        });
    if energies.is_empty() {
        (elo, ehi) = (0.0, 1.0);
    }
    // A flat energy (converged at once) gets a band of ±1e-5 relative: short tick labels.
    let pad = ((ehi - elo) * 0.05)
        .max(1e-5 * elo.abs().max(ehi.abs()))
        .max(1e-300);
    let (elo, ehi) = (elo - pad, ehi + pad);
    let e_step = nice_step(ehi - elo, 5.0);
    let e_ticks = ticks(elo, ehi, e_step);

    // Margins from the widest y label.
    let r_labels: Vec<String> = r_ticks.iter().map(|&e| decade_label(e)).collect();
    let e_labels: Vec<String> = e_ticks.iter().map(|&v| linear_label(v, e_step)).collect();
    let label_chars = r_labels
        .iter()
        .chain(&e_labels)
        .map(|l| l.chars().count())
        .max()
        .unwrap_or(1);
    let left = (label_chars as f64 + 2.0) * cw;
    let right = 3.0 * cw;
    let top = 3.0 * ch;
    let gap = 4.5 * ch;
    let bottom = 5.0 * ch;
    let pw = (wf - left - right).max(10.0).round();
    let avail = (hf - top - gap - bottom).max(20.0);
    let (h1, h2) = ((0.55 * avail).round(), (0.45 * avail).round());
    let p1 = Panel {
        x: left.round(),
        y: top.round(),
        w: pw,
        h: h1,
        x_range,
        y_range: (rlo as f64, rhi as f64),
    };
    let p2 = Panel {
        x: left.round(),
        y: (top + h1 + gap).round(),
        w: pw,
        h: h2,
        x_range,
        y_range: (elo, ehi),
    };
    let x_ticks = ticks(x_range.0, x_range.1, x_step);

    let text = |x: f64, y: f64, t: &str, anchor: Anchor, color: [u8; 3]| Prim::Text {
        x,
        y,
        text: t.to_string(),
        scale: s,
        anchor,
        color,
    };

    // Grid, frame, ticks, labels of a panel.
    let mut axes =
        |p: &Panel, y_ticks: &[(f64, String)], title: &str, legend: &[(&str, [u8; 3], bool)]| {
            for &(v, _) in y_ticks {
                let y = p.map(0.0, v)[1].round();
                prims.push(Prim::Rect {
                    x: p.x,
                    y,
                    w: p.w,
                    h: thin,
                    color: GRID,
                });
            }
            for &t in &x_ticks {
                let x = p.map(t, p.y_range.0)[0].round();
                prims.push(Prim::Rect {
                    x,
                    y: p.y,
                    w: thin,
                    h: p.h,
                    color: GRID,
                });
            }
            for (x, y, w, h) in [
                (p.x, p.y, p.w + thin, thin),
                (p.x, p.y + p.h, p.w + thin, thin),
                (p.x, p.y, thin, p.h + thin),
                (p.x + p.w, p.y, thin, p.h + thin),
            ] {
                prims.push(Prim::Rect {
                    x,
                    y,
                    w,
                    h,
                    color: AXIS,
                });
            }
            for (v, label) in y_ticks {
                let y = p.map(0.0, *v)[1].round();
                prims.push(Prim::Rect {
                    x: p.x - 0.8 * cw,
                    y,
                    w: 0.8 * cw,
                    h: thin,
                    color: AXIS,
                });
                prims.push(text(p.x - cw, y - 0.5 * ch, label, Anchor::End, INK));
            }
            for &t in &x_ticks {
                let x = p.map(t, p.y_range.0)[0].round();
                prims.push(Prim::Rect {
                    x,
                    y: p.y + p.h,
                    w: thin,
                    h: 0.8 * cw,
                    color: AXIS,
                });
            }
            prims.push(text(p.x, p.y - 1.8 * ch, title, Anchor::Start, INK));
            // Legend, right-aligned on the title line: a swatch (line or dot) and a label each.
            let mut x = p.x + p.w;
            for &(label, color, dot) in legend.iter().rev() {
                x -= Canvas::text_width(label, s) as f64;
                prims.push(text(x, p.y - 1.8 * ch, label, Anchor::Start, INK));
                x -= 4.0 * cw;
                let yc = p.y - 1.8 * ch + 0.5 * ch;
                if dot {
                    prims.push(Prim::Dot {
                        x: x + 1.5 * cw,
                        y: yc,
                        r: 2.0 * sc,
                        color,
                    });
                } else {
                    prims.push(Prim::Line {
                        pts: vec![[x + 0.5 * cw, yc], [x + 3.0 * cw, yc]],
                        width: line_w,
                        color,
                    });
                }
                x -= 2.0 * cw;
            }
        };

    let r_tick_vals: Vec<(f64, String)> = r_ticks.iter().map(|&e| e as f64).zip(r_labels).collect();
    let e_tick_vals: Vec<(f64, String)> = e_ticks.iter().copied().zip(e_labels).collect();
    let any_recovered = history
        .iter()
        .any(|h| h.recovered_energy.is_some_and(f64::is_finite));
    axes(
        &p1,
        &r_tick_vals,
        "residuals (log10)",
        &[("primal", PRIMAL, false), ("dual", DUAL, false)],
    );
    let mut e_legend = vec![("energy", ENERGY, false)];
    if any_recovered {
        e_legend.push(("recovered map", RECOVERED, true));
    }
    axes(&p2, &e_tick_vals, "energy", &e_legend);

    // X labels under the bottom panel.
    for &t in &x_ticks {
        let x = p2.map(t, elo)[0].round();
        let label = format!("{}", t.round() as i64);
        prims.push(text(x, p2.y + p2.h + 1.4 * cw, &label, Anchor::Middle, INK));
    }
    prims.push(text(
        p2.x + 0.5 * p2.w,
        p2.y + p2.h + 1.4 * cw + 2.0 * ch,
        "iteration",
        Anchor::Middle,
        INK,
    ));

    // Data.
    if history.is_empty() {
        for p in [&p1, &p2] {
            prims.push(text(
                p.x + 0.5 * p.w,
                p.y + 0.5 * p.h - 0.5 * ch,
                "no iterations",
                Anchor::Middle,
                INK,
            ));
        }
    }
    let series: [Series; 2] = [(|h| h.primal, PRIMAL), (|h| h.dual, DUAL)];
    for (get, color) in series {
        let pts = history
            .iter()
            .map(|h| positive_log(get(h)).map(|l| p1.map(h.iteration as f64, l)));
        for run in runs(pts) {
            prims.push(Prim::Line {
                pts: run,
                width: line_w,
                color,
            });
        }
    }
    let pts = history
        .iter()
        .map(|h| finite(h.energy).map(|e| p2.map(h.iteration as f64, e)));
    for run in runs(pts) {
        prims.push(Prim::Line {
            pts: run,
            width: line_w,
            color: ENERGY,
        });
    }
    for h in history {
        if let Some(e) = h.recovered_energy.and_then(finite) {
            let [x, y] = p2.map(h.iteration as f64, e);
            prims.push(Prim::Dot {
                x,
                y,
                r: 2.0 * sc,
                color: RECOVERED,
            });
        }
    }
    Figure {
        w: w.max(1),
        h: h.max(1),
        prims,
    }
}

fn hex(c: [u8; 3]) -> String {
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// SVG (960×640 px) of the run's convergence: primal and dual residuals against the iteration
/// on a log10 axis, the energy below on a linear axis with the energies of recovered maps as
/// dots. An empty history (no solver) gives empty axes saying so.
pub fn convergence_svg(history: &[History]) -> String {
    let fig = figure(history, SVG_SIZE.0, SVG_SIZE.1);
    let mut out = String::new();
    let _ = writeln!(out, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif">"#,
        w = fig.w,
        h = fig.h
    );
    let _ = writeln!(
        out,
        "<title>ADMM convergence: {} residual checks</title>",
        history.len()
    );
    let _ = writeln!(
        out,
        r#"<rect width="{}" height="{}" fill="{}"/>"#,
        fig.w,
        fig.h,
        hex(BG)
    );
    for p in &fig.prims {
        match p {
            Prim::Rect { x, y, w, h, color } => {
                let _ = writeln!(
                    out,
                    r#"<rect x="{x:.1}" y="{y:.1}" width="{w:.1}" height="{h:.1}" fill="{}" shape-rendering="crispEdges"/>"#,
                    hex(*color)
                );
            }
            Prim::Line { pts, width, color } => {
                let mut points = String::new();
                for p in pts {
                    let _ = write!(points, "{:.2},{:.2} ", p[0], p[1]);
                }
                let _ = writeln!(
                    out,
                    r#"<polyline fill="none" stroke="{}" stroke-width="{width:.2}" stroke-linejoin="round" stroke-linecap="round" points="{}"/>"#,
                    hex(*color),
                    points.trim_end()
                );
            }
            Prim::Dot { x, y, r, color } => {
                let _ = writeln!(
                    out,
                    r#"<circle cx="{x:.2}" cy="{y:.2}" r="{r:.2}" fill="{}"/>"#,
                    hex(*color)
                );
            }
            Prim::Text {
                x,
                y,
                text,
                scale,
                anchor,
                color,
            } => {
                let sc = *scale as f64;
                let a = match anchor {
                    Anchor::Start => "start",
                    Anchor::Middle => "middle",
                    Anchor::End => "end",
                };
                let _ = writeln!(
                    out,
                    r#"<text x="{x:.1}" y="{:.1}" font-size="{:.1}" text-anchor="{a}" fill="{}">{}</text>"#,
                    y + 7.0 * sc,
                    9.6 * sc,
                    hex(*color),
                    escape(text)
                );
            }
        }
    }
    let _ = writeln!(out, "</svg>");
    out
}

fn render(fig: &Figure) -> Canvas {
    let mut cv = Canvas::new(fig.w, fig.h, BG);
    for p in &fig.prims {
        match p {
            Prim::Rect { x, y, w, h, color } => cv.fill_rect(*x, *y, x + w, y + h, *color),
            Prim::Line { pts, width, color } => {
                if let [only] = pts.as_slice() {
                    cv.disc(only[0], only[1], 0.5 * width + 0.5, *color);
                }
                for seg in pts.windows(2) {
                    cv.line(seg[0], seg[1], *width, *color);
                }
            }
            Prim::Dot { x, y, r, color } => cv.disc(*x, *y, *r, *color),
            Prim::Text {
                x,
                y,
                text,
                scale,
                anchor,
                color,
            } => {
                let tw = Canvas::text_width(text, *scale) as f64;
                let x0 = match anchor {
                    Anchor::Start => *x,
                    Anchor::Middle => x - 0.5 * tw,
                    Anchor::End => x - tw,
                };
                cv.text(x0.round(), y.round(), text, *scale, *color);
            }
        }
    }
    cv
}

/// PNG bytes of the convergence plot at `w`×`h` px (each clamped to 1..=8192), the same
/// figure as [`convergence_svg`] with our 5×7 font for the labels. Empty only if the encoder
/// fails, which it does not for in-memory output; [`try_convergence_png`] passes the error on.
pub fn convergence_png(history: &[History], w: u32, h: u32) -> Vec<u8> {
    try_convergence_png(history, w, h).unwrap_or_default()
}

/// [`convergence_png`] with the encoder's error.
pub fn try_convergence_png(history: &[History], w: u32, h: u32) -> io::Result<Vec<u8>> {
    render_png(history, w, h)
}

pub(crate) fn render_png(history: &[History], w: u32, h: u32) -> io::Result<Vec<u8>> {
    let (w, h) = (
        w.clamp(1, super::raster::MAX_SIDE),
        h.clamp(1, super::raster::MAX_SIDE),
    );
    render(&figure(history, w, h)).encode_png()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_and_labels() {
        assert_eq!(nice_step(100.0, 5.0), 20.0);
        assert_eq!(nice_step(1.0, 5.0), 0.2);
        assert_eq!(ticks(0.0, 1.0, 0.25), vec![0.0, 0.25, 0.5, 0.75, 1.0]);
        assert_eq!(decade_label(-3), "1e-3");
        assert_eq!(decade_label(0), "1");
        assert_eq!(linear_label(2.5, 0.5), "2.5");
        assert_eq!(linear_label(-0.0, 0.5), "0.0");
    }

    #[test]
    fn gaps_break_lines() {
        let r = runs([Some([0.0, 0.0]), None, Some([1.0, 1.0]), Some([2.0, 2.0])].into_iter());
        assert_eq!(r.len(), 2);
        assert_eq!(r[1].len(), 2);
    }
}
