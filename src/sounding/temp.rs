//! Stage 1 — ingest: WMO FM-35 TEMP reader. In: the text of one or more raw TEMP messages as the
//! GTS distributes them (bulletins of `TTAA` / `TTBB` / `TTCC` / `TTDD` parts, with or without
//! their abbreviated headings). Out: metadata and raw rows for [`super::validate`], which gives
//! every level without a reported height (the surface and the significant levels) a hypsometric
//! one.
//!
//! The code (WMO-No. 306, Manual on Codes, FM 35), as far as this reader needs it:
//!
//! ```text
//! TTAA YYGGId IIiii 99PPP TTTDD dddff  PPhhh TTTDD dddff …  88PPP … 77PPP …  31313 … 8GGgg
//! TTBB YYGGa4 IIiii nnPPP TTTDD nnPPP TTTDD …  21212 (winds) 31313 41414 51515 …
//! TTCC YYGGId IIiii PPhhh TTTDD dddff …  88PPP …
//! TTDD YYGG/  IIiii nnPPP TTTDD …
//! ```
//!
//! * `YY` day of month (+50 when winds are in knots), `GG` hour UTC, `IIiii` WMO block and
//!   station number. The code carries neither year nor month, so the metadata get
//!   `nominal_day_hour_utc` (`"06 00"`) and no `nominal_time_utc`; the 31313 section's `8GGgg`
//!   gives `launch_hour_minute_utc`.
//! * Part A: the surface (`99PPP`, hPa, `PPP` < 100 meaning 1PPP) and the standard surfaces
//!   1000 (`00`), 925 (`92`), 850, 700, 500, 400, 300, 250, 200, 150, 100 hPa, each `PPhhh TTTDD`
//!   and a wind group `dddff` up to the last surface with wind, named by `Id` (the hundreds
//!   figure of its pressure: `0` 1000 hPa, `9` 925, … `2` 250 or 200, `1` 150 or 100; `/` no
//!   wind). A station may leave out surfaces (Danmarkshavn sends no 1000 or 925 hPa); surfaces
//!   under the ground come with `/////` and are skipped. `88PPP` (tropopause), `77PPP`/`66PPP`
//!   (maximum wind) and any later section end the standard surfaces.
//! * Part C: the same for 70, 50, 30, 20 and 10 hPa (`Id` `7` … `1`).
//! * Parts B and D: significant levels `nnPPP TTTDD`, `nn` = 00 (surface, Part B only), 11, 22,
//!   … 99, 11, …; `PPP` whole hPa in B (< 100 meaning 1PPP), tenths of hPa in D. The first
//!   section indicator (`21212` winds, `31313`, `41414`, `51515` … regional, `61616` … national)
//!   ends them: the groups after `51515` look like levels but are regional data.
//! * `hhh`: the height with its leading figures dropped — metres up to 700 hPa (thousands
//!   dropped), decametres above (ten-thousands dropped). The dropped figures are restored as the
//!   ones that put the height nearest the level's height in the ICAO standard atmosphere (every
//!   real height lies well within ±500 m, ±5000 m above 700 hPa, of it; GEMPAK's `RU_HGHT` uses
//!   fixed thresholds to the same effect); at 1000 hPa, 500 added means below sea level.
//! * `TTTDD`: `TTT` the temperature in tenths of °C, the parity of the tenths figure its sign
//!   (even ≥ 0, odd < 0); `DD` the dewpoint depression, 00–50 tenths of a kelvin, 56–99 whole
//!   kelvins plus 50 (51–55 unused); `/` missing.
//!
//! Where a part is sent more than once (corrections, repeats in a collection), the first copy
//! that holds levels is read and a warning names the others; parts of other stations, or of the
//! same station at another day and hour, are ignored with a warning. A level of Part B or D at
//! the pressure of a standard surface is that surface (Part A/C keeps its height). Errors name
//! file, line and group.
//!
//! Hand-written: no Rust crate decodes FM-35 TEMP (rweather-decoder reads METAR only; the ecCodes
//! bindings read BUFR and GRIB, not the alphanumeric codes; fm35_decoder is Python), and the code
//! is a few dozen group rules.

use std::collections::BTreeMap;
use std::path::Path;

use super::HeightSource;
use super::error::SoundingError;
use super::validate::{ColumnNames, Quantity, RawHumidity, RawRow, check_range};
use crate::units;

/// A part of a TEMP report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Part {
    A,
    B,
    C,
    D,
}

impl Part {
    fn name(self) -> &'static str {
        match self {
            Part::A => "TTAA",
            Part::B => "TTBB",
            Part::C => "TTCC",
            Part::D => "TTDD",
        }
    }
}

/// One whitespace-separated group of a message and its 1-based line.
#[derive(Debug, Clone, Copy)]
struct Group<'t> {
    text: &'t str,
    line: usize,
}

/// How a message ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ending {
    /// At `=` or a blank line, as the code ends a message.
    Terminated,
    /// At a heading, the next part or the end of the file, without `=`.
    Unterminated,
}

/// One part as found in the text: the groups after its `TTAA`-like marker.
#[derive(Debug)]
struct Message<'t> {
    /// `None` for a part of another code form (PILOT `PPBB`, ship `UUAA` …), which is skipped.
    part: Option<Part>,
    /// The line of the marker.
    line: usize,
    /// `YYGGI`, `IIiii`, then the body.
    groups: Vec<Group<'t>>,
    ending: Ending,
}

impl Message<'_> {
    fn station(&self) -> Option<&str> {
        self.groups.get(1).map(|g| g.text)
    }

    /// `YYGG` of the `YYGGI` group.
    fn day_hour(&self) -> Option<&str> {
        self.groups.first().and_then(|g| g.text.get(..4))
    }

    fn body(&self) -> &[Group<'_>] {
        self.groups.get(2..).unwrap_or(&[])
    }
}

/// Whether a token is the marker of a part: `TTAA` … `TTDD` (TEMP, read), or the same letters of
/// PILOT, TEMP SHIP/MOBIL/DROP and PILOT SHIP/MOBIL (skipped). `Some(None)` for the skipped ones.
fn marker(token: &str) -> Option<Option<Part>> {
    let b = token.as_bytes();
    if b.len() != 4 || b[0] != b[1] || b[2] != b[3] || !b"TPUIXQE".contains(&b[0]) {
        return None;
    }
    let part = match b[2] {
        b'A' => Part::A,
        b'B' => Part::B,
        b'C' => Part::C,
        b'D' => Part::D,
        _ => return None,
    };
    Some((b[0] == b'T').then_some(part))
}

fn all(text: &str, n: usize, pred: impl Fn(u8) -> bool) -> bool {
    text.len() == n && text.bytes().all(pred)
}

/// A bulletin heading (`USRA02 RUHB 060000`) or an AWIPS identifier line (`MANBRW`, `NNNN`).
fn is_heading(tokens: &[&str]) -> bool {
    let upper_digits = |t: &str| {
        t.len() == 6
            && t.as_bytes()[..4].iter().all(u8::is_ascii_uppercase)
            && t.as_bytes()[4..].iter().all(u8::is_ascii_digit)
    };
    let bulletin = tokens.len() >= 3
        && upper_digits(tokens[0])
        && all(tokens[1], 4, |b| b.is_ascii_uppercase())
        && all(tokens[2], 6, |b| b.is_ascii_digit());
    let awips = tokens.len() == 1
        && (4..=6).contains(&tokens[0].len())
        && tokens[0].as_bytes()[0].is_ascii_uppercase()
        && tokens[0]
            .bytes()
            .all(|b| b.is_ascii_uppercase() || b.is_ascii_digit());
    bulletin || awips
}

/// Splits the text into parts. A part runs from its marker to `=`, a blank line, a heading, the
/// next marker or the end of the text; tokens before the marker on its line (a station prefix,
/// `70026 TTAA`) and text outside parts are not read.
fn messages(text: &str) -> Vec<Message<'_>> {
    let mut out = Vec::new();
    let mut current: Option<Message> = None;
    // A part ending in `=` may be followed by the next on the same line: each `=` ends a
    // segment, and segments are read like lines.
    let segments = text.lines().enumerate().flat_map(|(index, line)| {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        let mut parts: Vec<Vec<&str>> = tokens
            .split_inclusive(|t| t.ends_with('='))
            .map(<[&str]>::to_vec)
            .collect();
        if parts.is_empty() {
            parts.push(Vec::new());
        }
        parts.into_iter().map(move |p| (index + 1, p))
    });
    for (number, tokens) in segments {
        let start = tokens.iter().position(|t| marker(t).is_some());
        if (tokens.is_empty() || start.is_some() || is_heading(&tokens))
            && let Some(mut m) = current.take()
        {
            if tokens.is_empty() {
                m.ending = Ending::Terminated;
            }
            out.push(m);
        }
        let rest = match start {
            Some(s) => {
                current = Some(Message {
                    part: marker(tokens[s]).flatten(),
                    line: number,
                    groups: Vec::new(),
                    ending: Ending::Unterminated,
                });
                &tokens[s + 1..]
            }
            None => &tokens[..],
        };
        let Some(m) = current.as_mut() else { continue };
        for token in rest {
            let (text, ends) = match token.strip_suffix('=') {
                Some(t) => (t, true),
                None => (*token, false),
            };
            if !text.is_empty() {
                m.groups.push(Group { text, line: number });
            }
            if ends {
                m.ending = Ending::Terminated;
                out.extend(current.take());
                break;
            }
        }
    }
    out.extend(current);
    out
}

/// Whether the text holds a TEMP report: a `TTAA` followed by a `YYGGId` group.
pub(crate) fn detect(text: &str) -> bool {
    text.lines().any(|line| {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        tokens.windows(2).any(|w| {
            w[0] == "TTAA"
                && w[1].len() == 5
                && w[1].as_bytes()[..4].iter().all(u8::is_ascii_digit)
                && (w[1].as_bytes()[4].is_ascii_digit() || w[1].as_bytes()[4] == b'/')
        })
    })
}

/// A standard isobaric surface of Part A or C.
struct Standard {
    /// The two figures that open its `PPhhh` group.
    indicator: &'static str,
    pressure_hpa: f64,
    /// The `Id` figure naming it as the last surface with wind.
    wind_code: u8,
    /// Its geopotential height in the ICAO (= US 1976) standard atmosphere (m).
    standard_height_m: f64,
    /// Metres per unit of `hhh`.
    unit_m: f64,
}

const fn standard(indicator: &'static str, p: f64, code: u8, h: f64, unit: f64) -> Standard {
    Standard {
        indicator,
        pressure_hpa: p,
        wind_code: code,
        standard_height_m: h,
        unit_m: unit,
    }
}

/// Part A's standard surfaces, bottom to top.
const PART_A_LEVELS: [Standard; 11] = [
    standard("00", 1000.0, b'0', 111.0, 1.0),
    standard("92", 925.0, b'9', 762.0, 1.0),
    standard("85", 850.0, b'8', 1457.0, 1.0),
    standard("70", 700.0, b'7', 3012.0, 1.0),
    standard("50", 500.0, b'5', 5574.0, 10.0),
    standard("40", 400.0, b'4', 7185.0, 10.0),
    standard("30", 300.0, b'3', 9164.0, 10.0),
    standard("25", 250.0, b'2', 10363.0, 10.0),
    standard("20", 200.0, b'2', 11784.0, 10.0),
    standard("15", 150.0, b'1', 13608.0, 10.0),
    standard("10", 100.0, b'1', 16180.0, 10.0),
];

/// Part C's standard surfaces, bottom to top.
const PART_C_LEVELS: [Standard; 5] = [
    standard("70", 70.0, b'7', 18442.0, 10.0),
    standard("50", 50.0, b'5', 20576.0, 10.0),
    standard("30", 30.0, b'3', 23849.0, 10.0),
    standard("20", 20.0, b'2', 26481.0, 10.0),
    standard("10", 10.0, b'1', 31055.0, 10.0),
];

/// The height (m) of `level` whose group gives `hhh`: the leading figures restored so the height
/// is nearest the standard atmosphere's; at 1000 hPa, `hhh` ≥ 500 is 500 − height.
fn restore_height(level: &Standard, hhh: u32) -> f64 {
    let value = f64::from(hhh) * level.unit_m;
    if level.pressure_hpa == 1000.0 {
        return if hhh >= 500 { 500.0 - value } else { value };
    }
    let modulus = 1000.0 * level.unit_m;
    value + modulus * ((level.standard_height_m - value) / modulus).round()
}

/// What a level of a part is, for merging.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Surface,
    Standard,
    Significant,
}

/// One decoded level (SI).
#[derive(Debug, Clone, PartialEq)]
struct Decoded {
    line: usize,
    kind: Kind,
    pressure_pa: f64,
    height_m: Option<f64>,
    temperature_k: Option<f64>,
    dewpoint_k: Option<f64>,
}

/// The file and part being decoded, for error messages.
#[derive(Clone, Copy)]
struct Ctx<'a> {
    path: &'a Path,
    part: Part,
}

impl Ctx<'_> {
    fn bad(&self, g: Group, message: impl Into<String>) -> SoundingError {
        SoundingError::field(
            self.path,
            g.line,
            format!("{} group {}", self.part.name(), g.text),
            message,
        )
    }

    fn truncated(&self, last: Group, what: &str) -> SoundingError {
        self.bad(
            last,
            format!(
                "the {} message ends here, but {what} must follow: it is truncated",
                self.part.name()
            ),
        )
    }

    /// `g` checked to be a group of five figures or `/`.
    fn figures<'t>(&self, g: Group<'t>) -> Result<&'t [u8], SoundingError> {
        if all(g.text, 5, |b| b.is_ascii_digit() || b == b'/') {
            Ok(g.text.as_bytes())
        } else {
            Err(self.bad(g, "not a group of five figures (0-9, or / for missing)"))
        }
    }
}

/// The number written by `figures` (all ASCII digits), or `None` if one is `/`.
fn number(figures: &[u8]) -> Option<u32> {
    figures.iter().try_fold(0u32, |n, &b| {
        b.is_ascii_digit().then(|| n * 10 + u32::from(b - b'0'))
    })
}

/// `TTTDD` → temperature and dewpoint (K), each `None` where the group has `/`.
fn temperature_group(ctx: Ctx, g: Group) -> Result<(Option<f64>, Option<f64>), SoundingError> {
    let f = ctx.figures(g)?;
    let Some(ttt) = number(&f[..3]) else {
        return Ok((None, None));
    };
    let tenths = if ttt % 2 == 1 {
        -(ttt as i32)
    } else {
        ttt as i32
    };
    let depression_tenths = match number(&f[3..]) {
        None => None,
        Some(dd @ 0..=50) => Some(dd as i32),
        Some(dd @ 56..=99) => Some((dd as i32 - 50) * 10),
        Some(dd) => {
            return Err(ctx.bad(
                g,
                format!("dewpoint depression figures {dd} are not used by the code (51-55)"),
            ));
        }
    };
    let kelvin = |t: i32, q| {
        let k = units::celsius_to_kelvin(f64::from(t) / 10.0);
        check_range(
            ctx.path,
            g.line,
            &format!("{} group {}", ctx.part.name(), g.text),
            q,
            k,
            g.text,
        )
    };
    let t = kelvin(tenths, Quantity::TemperatureC)?;
    let td = depression_tenths
        .map(|d| kelvin(tenths - d, Quantity::DewpointC))
        .transpose()?;
    Ok((Some(t), td))
}

/// Whether `g` reads as a wind group `dddff`: missing, or a direction (rounded to 5°, with the
/// hundreds of the speed added to its last figure) of at most 360° and a speed under 300.
fn plausible_wind(g: Group) -> bool {
    if g.text == "/////" {
        return true;
    }
    let b = g.text.as_bytes();
    let Some(ddd) = (b.len() == 5).then(|| number(&b[..3])).flatten() else {
        return false;
    };
    ddd - ddd % 5 <= 360 && ddd % 5 <= 2 && (number(&b[3..]).is_some() || &b[3..] == b"//")
}

/// Whether `g` ends the standard surfaces: tropopause `88`, maximum wind `77`/`66`, or a section
/// indicator.
fn ends_standard_levels(g: Group) -> bool {
    ["88", "77", "66"].iter().any(|p| g.text.starts_with(p)) || is_section_indicator(g)
}

/// A section indicator `21212`, `31313`, `41414`, `51515` … `59595`, `61616` … `69696`: five
/// figures alternating between two different ones.
fn is_section_indicator(g: Group) -> bool {
    let b = g.text.as_bytes();
    all(g.text, 5, |c| c.is_ascii_digit())
        && b[0] != b[1]
        && b[0] == b[2]
        && b[2] == b[4]
        && b[1] == b[3]
}

/// Whether the standard surface `k` of `table` has a wind group under `id` (`None`: `Id` is `/`,
/// no wind at any standard surface): `Some(true/false)`, or `None` when `id` names two surfaces
/// (250/200, 150/100 hPa) and `k` is the upper one.
fn wind_expected(table: &[Standard], k: usize, id: Option<u8>) -> Option<bool> {
    let Some(id) = id else {
        return Some(false);
    };
    let first = table.iter().position(|l| l.wind_code == id);
    let last = table.iter().rposition(|l| l.wind_code == id);
    match (first, last) {
        (Some(f), Some(l)) if k > f && k <= l => None,
        (Some(f), _) => Some(k <= f),
        _ => Some(false),
    }
}

/// For a surface whose wind group may or may not follow at `body[j]`: whether it does. A group
/// that cannot be a wind, or could be but is followed by one that cannot start the next level,
/// settles it.
fn wind_follows(body: &[Group], j: usize, rest: &[Standard]) -> bool {
    let starts_next =
        |g: Group| ends_standard_levels(g) || rest.iter().any(|l| g.text.starts_with(l.indicator));
    let Some(&g1) = body.get(j) else {
        return false;
    };
    if !plausible_wind(g1) {
        return false;
    }
    if !starts_next(g1) {
        return true;
    }
    body.get(j + 1).is_none_or(|&g2| starts_next(g2))
}

/// The `Id` figure of `YYGGId` (`None`: `/`, no winds), checked against `table`.
fn wind_indicator(ctx: Ctx, yyggi: Group, table: &[Standard]) -> Result<Option<u8>, SoundingError> {
    let id = yyggi.text.as_bytes()[4];
    if id == b'/' {
        return Ok(None);
    }
    if table.iter().any(|l| l.wind_code == id) {
        return Ok(Some(id));
    }
    Err(ctx.bad(
        yyggi,
        format!(
            "Id = {} names no standard surface of {}",
            id as char,
            ctx.part.name()
        ),
    ))
}

/// `PPP` of a whole-hPa pressure group: figures under 100 stand for 1PPP.
fn whole_hpa(ppp: u32) -> f64 {
    f64::from(if ppp < 100 { 1000 + ppp } else { ppp })
}

/// Part A's surface, `99PPP TTTDD dddff` at the start of `body` (not empty).
fn surface(ctx: Ctx, body: &[Group]) -> Result<Decoded, SoundingError> {
    let g = body[0];
    let f = ctx.figures(g)?;
    let (b"99", Some(ppp)) = (&f[..2], number(&f[2..])) else {
        return Err(ctx.bad(
            g,
            "expected the surface group 99PPP (surface pressure, whole hPa)",
        ));
    };
    let t_group = *body
        .get(1)
        .ok_or_else(|| ctx.truncated(g, "the surface's temperature group TTTDD"))?;
    let (temperature_k, dewpoint_k) = temperature_group(ctx, t_group)?;
    if body.get(2).is_none() {
        return Err(ctx.truncated(t_group, "the surface's wind group dddff"));
    }
    Ok(Decoded {
        line: g.line,
        kind: Kind::Surface,
        pressure_pa: units::hpa_to_pa(whole_hpa(ppp)),
        height_m: None,
        temperature_k,
        dewpoint_k,
    })
}

/// The surface (Part A) and the standard surfaces of Part A or C, up to the first group that
/// ends them.
fn standard_levels(
    ctx: Ctx,
    message: &Message,
    table: &[Standard],
) -> Result<Vec<Decoded>, SoundingError> {
    let body = message.body();
    let id = wind_indicator(ctx, message.groups[0], table)?;
    let mut out = Vec::new();
    let mut i = 0;
    if ctx.part == Part::A && !body.is_empty() {
        out.push(surface(ctx, body)?);
        i = 3;
    }
    let mut next = 0;
    while let Some(&g) = body.get(i) {
        if ends_standard_levels(g) {
            break;
        }
        let f = ctx.figures(g)?;
        let Some(offset) = table[next..]
            .iter()
            .position(|l| g.text.starts_with(l.indicator))
        else {
            let names: Vec<&str> = table[next..].iter().map(|l| l.indicator).collect();
            return Err(ctx.bad(
                g,
                format!(
                    "expected PPhhh of a standard surface above the last one (PP = {}), or 88PPP",
                    names.join(", ")
                ),
            ));
        };
        let k = next + offset;
        let t_group = *body
            .get(i + 1)
            .ok_or_else(|| ctx.truncated(g, "its temperature group TTTDD"))?;
        let (temperature_k, dewpoint_k) = temperature_group(ctx, t_group)?;
        let wind = wind_expected(table, k, id)
            .unwrap_or_else(|| wind_follows(body, i + 2, &table[k + 1..]));
        if wind && body.get(i + 2).is_none() {
            return Err(ctx.truncated(t_group, "its wind group dddff"));
        }
        out.push(Decoded {
            line: g.line,
            kind: Kind::Standard,
            pressure_pa: units::hpa_to_pa(table[k].pressure_hpa),
            height_m: number(&f[2..]).map(|hhh| restore_height(&table[k], hhh)),
            temperature_k,
            dewpoint_k,
        });
        i += if wind { 3 } else { 2 };
        next = k + 1;
    }
    Ok(out)
}

/// The significant levels `nnPPP TTTDD` of Part B or D, up to the first section indicator.
fn significant_levels(ctx: Ctx, message: &Message) -> Result<Vec<Decoded>, SoundingError> {
    let body = message.body();
    let mut out = Vec::new();
    let mut expected: Option<u8> = None;
    let mut i = 0;
    while let Some(&g) = body.get(i) {
        if is_section_indicator(g) {
            break;
        }
        let f = ctx.figures(g)?;
        let nn = f[0];
        if !nn.is_ascii_digit() || f[1] != nn || expected.is_some_and(|e| e != nn) {
            let want = expected.map_or("00, 11, 22, … 99".to_string(), |e| {
                format!("{0}{0}", e as char)
            });
            return Err(ctx.bad(
                g,
                format!("expected a significant level nnPPP with nn = {want}, or a section indicator such as 21212"),
            ));
        }
        expected = Some(if nn == b'9' { b'1' } else { nn + 1 });
        let Some(ppp) = number(&f[2..]) else {
            return Err(ctx.bad(g, "the level's pressure PPP is missing"));
        };
        let hpa = match ctx.part {
            Part::D => f64::from(ppp) / 10.0,
            _ => whole_hpa(ppp),
        };
        let column = format!("{} group {}", ctx.part.name(), g.text);
        let pressure_pa = check_range(
            ctx.path,
            g.line,
            &column,
            Quantity::PressureHpa,
            units::hpa_to_pa(hpa),
            g.text,
        )?;
        let t_group = *body
            .get(i + 1)
            .ok_or_else(|| ctx.truncated(g, "its temperature group TTTDD"))?;
        let (temperature_k, dewpoint_k) = temperature_group(ctx, t_group)?;
        out.push(Decoded {
            line: g.line,
            kind: if nn == b'0' {
                Kind::Surface
            } else {
                Kind::Significant
            },
            pressure_pa,
            height_m: None,
            temperature_k,
            dewpoint_k,
        });
        i += 2;
    }
    Ok(out)
}

/// Checks a message's `YYGGI IIiii`; returns its day and hour (UTC).
fn header(path: &Path, part: Part, message: &Message) -> Result<(u32, u32), SoundingError> {
    let ctx = Ctx { path, part };
    let (Some(&yyggi), Some(&station)) = (message.groups.first(), message.groups.get(1)) else {
        return Err(SoundingError::line_error(
            path,
            message.line,
            format!(
                "the {} message has no YYGGI and IIiii groups: it is truncated",
                part.name()
            ),
        ));
    };
    let f = ctx.figures(yyggi)?;
    let (Some(yy), Some(hour)) = (number(&f[..2]), number(&f[2..4])) else {
        return Err(ctx.bad(yyggi, "the day YY and hour GG must be figures"));
    };
    let day = if yy > 50 { yy - 50 } else { yy };
    if !(1..=31).contains(&day) || hour > 23 {
        return Err(ctx.bad(
            yyggi,
            "the day YY must be 1-31 (51-81 when winds are in knots) and the hour GG 00-23",
        ));
    }
    if !all(station.text, 5, |b| b.is_ascii_digit()) {
        return Err(ctx.bad(station, "the station IIiii must be five figures"));
    }
    Ok((day, hour))
}

/// The levels of one copy of a part (none for a `NIL` part).
fn decode(path: &Path, part: Part, message: &Message) -> Result<Vec<Decoded>, SoundingError> {
    header(path, part, message)?;
    let ctx = Ctx { path, part };
    if message.body().first().is_some_and(|g| g.text == "NIL") {
        return Ok(Vec::new());
    }
    match part {
        Part::A => standard_levels(ctx, message, &PART_A_LEVELS),
        Part::C => standard_levels(ctx, message, &PART_C_LEVELS),
        Part::B | Part::D => significant_levels(ctx, message),
    }
}

/// The levels of the first of `copies` (all of one part) that holds levels, with its line;
/// warnings name the copies not read, and a copy read that did not end at `=` or a blank line.
fn read_part(
    path: &Path,
    part: Part,
    copies: &[&Message],
    warnings: &mut Vec<String>,
) -> Result<Option<(usize, Vec<Decoded>)>, SoundingError> {
    let mut chosen = None;
    for message in copies {
        let levels = decode(path, part, message)?;
        if !levels.is_empty() {
            chosen = Some((*message, levels));
            break;
        }
    }
    if copies.len() > 1 {
        let lines: Vec<String> = copies.iter().map(|m| m.line.to_string()).collect();
        let what = match &chosen {
            Some((m, _)) => format!(
                "read the one at line {}, the first that holds levels; the others were ignored",
                m.line
            ),
            None => "none holds levels".to_string(),
        };
        warnings.push(format!(
            "{} appears {} times (lines {}): {what}",
            part.name(),
            copies.len(),
            lines.join(", ")
        ));
    }
    if let Some((m, _)) = &chosen
        && m.ending == Ending::Unterminated
    {
        warnings.push(format!(
            "the {} at line {} ends without \"=\" or a blank line (at a heading, another part or \
             the end of the file): it may be truncated",
            part.name(),
            m.line
        ));
    }
    Ok(chosen.map(|(m, levels)| (m.line, levels)))
}

/// The copies of `part` for `station` at the day and hour `day_hour` (`YYGG` of the first
/// TTAA); copies of the station at another day or hour are named in a warning.
fn copies_of<'m, 't>(
    messages: &[&'m Message<'t>],
    part: Part,
    station: &str,
    day_hour: Option<&str>,
    warnings: &mut Vec<String>,
) -> Vec<&'m Message<'t>> {
    let mut out = Vec::new();
    for m in messages {
        if m.part != Some(part) || m.station() != Some(station) {
            continue;
        }
        if m.day_hour() == day_hour {
            out.push(*m);
        } else {
            warnings.push(format!(
                "ignored the {} at line {}: its day and hour {} differ from the first TTAA's {}",
                part.name(),
                m.line,
                m.day_hour().unwrap_or("?"),
                day_hour.unwrap_or("?")
            ));
        }
    }
    out
}

/// A warning naming the stations other than `station` whose parts the file holds.
fn other_stations(messages: &[&Message], station: &str) -> Option<String> {
    let mut others: Vec<(&str, usize)> = Vec::new();
    for m in messages {
        if let Some(s) = m.station()
            && s != station
            && !others.iter().any(|(o, _)| *o == s)
        {
            others.push((s, m.line));
        }
    }
    const SHOWN: usize = 10;
    let mut list: Vec<String> = others
        .iter()
        .take(SHOWN)
        .map(|(s, line)| format!("{s} (from line {line})"))
        .collect();
    if others.len() > SHOWN {
        list.push(format!("… ({} more)", others.len() - SHOWN));
    }
    (!others.is_empty()).then(|| {
        format!(
            "the file holds TEMP parts of {} other station(s), not read: {}; only station \
             {station}, that of the first TTAA, was read",
            others.len(),
            list.join(", ")
        )
    })
}

/// `HH:MM` of the first `31313 srrarasasa 8GGgg` in `messages`, if any is well formed.
fn launch_time(messages: &[&Message]) -> Option<String> {
    messages
        .iter()
        .flat_map(|m| m.body().windows(3))
        .find_map(|w| {
            let b = w[2].text.as_bytes();
            if w[0].text != "31313" || b.len() != 5 || b[0] != b'8' {
                return None;
            }
            let (hh, mm) = (number(&b[1..3])?, number(&b[3..5])?);
            (hh < 24 && mm < 60).then(|| format!("{hh:02}:{mm:02}"))
        })
}

/// The decoded levels of every part as raw rows, bottom to top: sorted by pressure; a level of
/// one part at the pressure of another's merged into it (the first keeps its height and line,
/// the second fills what the first lacks; differing temperatures are named in a warning);
/// levels under the surface dropped with a warning.
fn assemble(mut decoded: Vec<Decoded>, warnings: &mut Vec<String>) -> Vec<RawRow> {
    // Stable: at equal pressure, Part A/C (with the height) stays before Part B/D.
    decoded.sort_by(|a, b| b.pressure_pa.total_cmp(&a.pressure_pa));
    let mut merged: Vec<Decoded> = Vec::with_capacity(decoded.len());
    let mut differing = Vec::new();
    for level in decoded {
        match merged.last_mut() {
            Some(prev) if prev.pressure_pa == level.pressure_pa => {
                if prev.temperature_k.is_none() {
                    (prev.temperature_k, prev.dewpoint_k) = (level.temperature_k, level.dewpoint_k);
                } else if level.temperature_k.is_some()
                    && (prev.temperature_k, prev.dewpoint_k)
                        != (level.temperature_k, level.dewpoint_k)
                {
                    differing.push(format!("line {} vs {}", prev.line, level.line));
                }
                prev.height_m = prev.height_m.or(level.height_m);
            }
            _ => merged.push(level),
        }
    }
    if !differing.is_empty() {
        warnings.push(format!(
            "levels reported twice at one pressure with different temperature or dewpoint (the \
             first kept): {}",
            differing.join(", ")
        ));
    }
    let surface_pa = merged
        .iter()
        .find(|l| l.kind == Kind::Surface)
        .map(|l| l.pressure_pa);
    let (below, above): (Vec<Decoded>, Vec<Decoded>) = merged
        .into_iter()
        .partition(|l| surface_pa.is_some_and(|s| l.pressure_pa > s));
    if let (Some(s), false) = (surface_pa, below.is_empty()) {
        let lines: Vec<String> = below.iter().map(|l| l.line.to_string()).collect();
        warnings.push(format!(
            "skipped {} standard surface(s) under the ground (pressure above the surface's {} \
             hPa; TEMP gives them extrapolated heights and no temperature): lines {}",
            below.len(),
            units::pa_to_hpa(s),
            lines.join(", ")
        ));
    }
    above.into_iter().map(raw_row).collect()
}

fn raw_row(level: Decoded) -> RawRow {
    RawRow {
        line: level.line,
        height_m: level.height_m,
        height_source: HeightSource::Measured,
        pressure_pa: Some(level.pressure_pa),
        temperature_k: level.temperature_k,
        humidity: level
            .dewpoint_k
            .map_or(RawHumidity::None, RawHumidity::DewpointK),
    }
}

/// Reads the TEMP report of the first TTAA's station: metadata (`station`,
/// `nominal_day_hour_utc`, `launch_hour_minute_utc`, `parts_read`) and raw rows of Parts A–D.
pub(crate) fn read(
    path: &Path,
    text: &str,
    metadata: &mut BTreeMap<String, String>,
    warnings: &mut Vec<String>,
) -> Result<(Vec<RawRow>, ColumnNames), SoundingError> {
    let all = messages(text);
    let temp: Vec<&Message> = all.iter().filter(|m| m.part.is_some()).collect();
    let Some(first_a) = temp.iter().copied().find(|m| m.part == Some(Part::A)) else {
        return Err(SoundingError::file(
            path,
            "no TTAA part (TEMP Part A) in the file",
        ));
    };
    let (day, hour) = header(path, Part::A, first_a)?;
    let station = first_a.station().unwrap_or_default();
    warnings.extend(other_stations(&temp, station));
    let mut decoded = Vec::new();
    let mut parts_read = Vec::new();
    let mut used = Vec::new();
    for part in [Part::A, Part::B, Part::C, Part::D] {
        let copies = copies_of(&temp, part, station, first_a.day_hour(), warnings);
        if let Some((line, levels)) = read_part(path, part, &copies, warnings)? {
            parts_read.push(format!("{} (line {line})", part.name()));
            used.extend(copies.iter().find(|m| m.line == line));
            decoded.extend(levels);
        }
    }
    metadata.insert("station".into(), station.to_string());
    metadata.insert("nominal_day_hour_utc".into(), format!("{day:02} {hour:02}"));
    if let Some(launch) = launch_time(&used) {
        metadata.insert("launch_hour_minute_utc".into(), launch);
    }
    metadata.insert("parts_read".into(), parts_read.join(", "));
    let names = ColumnNames {
        height: "PPhhh".into(),
        pressure: "PPP".into(),
        humidity: "TTTDD".into(),
    };
    Ok((assemble(decoded, warnings), names))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::us1976::us1976_at_geopotential;

    fn g(text: &str) -> Group<'_> {
        Group { text, line: 1 }
    }

    fn ctx() -> Ctx<'static> {
        Ctx {
            path: Path::new("t"),
            part: Part::A,
        }
    }

    #[test]
    fn standard_heights_are_the_us1976_ones() {
        // The table's heights put the US 1976 atmosphere within 1.5 m of each surface's pressure
        // (dp/p per metre is g/(R T) ≈ 1.2e-4 at the ground, less aloft).
        for level in PART_A_LEVELS.iter().chain(&PART_C_LEVELS) {
            let air = us1976_at_geopotential(level.standard_height_m, 288.15, 101_325.0);
            let p = units::hpa_to_pa(level.pressure_hpa);
            let per_m = units::STANDARD_GRAVITY_M_S2
                / (units::DRY_AIR_GAS_CONSTANT_J_KG_K * air.temperature_k);
            let off_m = (air.pressure_pa / p).ln() / per_m;
            assert!(off_m.abs() < 1.5, "{} hPa: {off_m} m", level.pressure_hpa);
        }
    }

    #[test]
    fn heights_get_their_dropped_figures_back() {
        let a = |pp: &str, hhh| {
            let level = PART_A_LEVELS.iter().find(|l| l.indicator == pp).unwrap();
            restore_height(level, hhh)
        };
        assert_eq!(a("00", 165), 165.0);
        assert_eq!(a("00", 541), -41.0);
        assert_eq!(a("92", 721), 721.0);
        assert_eq!(a("85", 354), 1354.0);
        assert_eq!(a("70", 817), 2817.0);
        assert_eq!(a("70", 300), 3300.0);
        assert_eq!(a("50", 522), 5220.0);
        assert_eq!(a("25", 976), 9760.0);
        assert_eq!(a("25", 40), 10_400.0);
        assert_eq!(a("20", 130), 11_300.0);
        assert_eq!(a("10", 553), 15_530.0);
        let c = |pp: &str, hhh| {
            let level = PART_C_LEVELS.iter().find(|l| l.indicator == pp).unwrap();
            restore_height(level, hhh)
        };
        assert_eq!(c("70", 825), 18_250.0);
        assert_eq!(c("50", 970), 19_700.0);
        assert_eq!(c("50", 53), 20_530.0);
        assert_eq!(c("10", 953), 29_530.0);
        assert_eq!(c("10", 19), 30_190.0);
    }

    #[test]
    fn temperature_sign_and_dewpoint_depression() {
        let c = |text| {
            let (t, td) = temperature_group(ctx(), g(text)).unwrap();
            (
                t.map(units::kelvin_to_celsius)
                    .map(|v| (v * 10.0).round() / 10.0),
                td.map(units::kelvin_to_celsius)
                    .map(|v| (v * 10.0).round() / 10.0),
            )
        };
        assert_eq!(c("34148"), (Some(-34.1), Some(-38.9)));
        assert_eq!(c("12445"), (Some(12.4), Some(7.9)));
        assert_eq!(c("10656"), (Some(10.6), Some(4.6)));
        assert_eq!(c("00099"), (Some(0.0), Some(-49.0)));
        assert_eq!(c("124//"), (Some(12.4), None));
        assert_eq!(c("/////"), (None, None));
        let e = temperature_group(ctx(), g("12452")).unwrap_err();
        assert!(e.to_string().contains("51-55"), "{e}");
        assert!(temperature_group(ctx(), g("1245")).is_err());
        assert!(temperature_group(ctx(), g("12é45")).is_err());
    }

    #[test]
    fn sections_and_winds() {
        for marker in ["21212", "31313", "41414", "51515", "61616"] {
            assert!(is_section_indicator(g(marker)), "{marker}");
        }
        for level in ["11111", "00020", "99334", "2121/"] {
            assert!(!is_section_indicator(g(level)), "{level}");
        }
        assert!(plausible_wind(g("24011")) && plausible_wind(g("/////")));
        // 880° and a 300-knot hundreds figure are not winds.
        assert!(!plausible_wind(g("88217")) && !plausible_wind(g("15304")));
    }

    fn levels(text: &str) -> Vec<(f64, Option<f64>)> {
        let all = messages(text);
        let levels = decode(Path::new("t"), all[0].part.unwrap(), &all[0]).unwrap();
        levels
            .iter()
            .map(|l| (units::pa_to_hpa(l.pressure_pa), l.height_m))
            .collect()
    }

    #[test]
    fn id_naming_two_surfaces_is_settled_by_the_next_groups() {
        // Id = 2: 250 hPa has a wind; 200 hPa has none here (15295 could be a wind, but the
        // group after it, 55567, cannot start a level), so 15295 opens the 150 hPa surface.
        let text = "TTAA 06002 25123 99020 34148 32001 25976 55563 15516 20130 53765 \
                    15295 55567 10552 58570 88999 77999=";
        assert_eq!(
            levels(text),
            [
                (1020.0, None),
                (250.0, Some(9760.0)),
                (200.0, Some(11_300.0)),
                (150.0, Some(12_950.0)),
                (100.0, Some(15_520.0))
            ]
        );
        // The same with a wind at 200 hPa.
        let text = "TTAA 06002 25123 99020 34148 32001 25976 55563 15516 20130 53765 \
                    16504 15295 55567 10552 58570 88999 77999=";
        assert_eq!(levels(text).len(), 5);
        // Id = 7: no wind from 500 hPa up.
        let text = "TTAA 06007 25123 99020 34148 32001 70817 19970 08513 50522 35767 \
                    40674 45168 88999=";
        assert_eq!(
            levels(text),
            [
                (1020.0, None),
                (700.0, Some(2817.0)),
                (500.0, Some(5220.0)),
                (400.0, Some(6740.0))
            ]
        );
        // Id = /: no wind at any standard surface (the surface's wind group stays).
        let text = "TTAA 0600/ 25123 99020 34148 32001 70817 19970 50522 35767 88999=";
        assert_eq!(levels(text).len(), 3);
    }

    #[test]
    fn significant_levels_wrap_and_stop_at_sections() {
        let mut text = String::from("TTBB 06003 25123 00020 34148");
        for (i, p) in (0..12).zip((900..1000).rev().step_by(8)) {
            let nn = [11, 22, 33, 44, 55, 66, 77, 88, 99][i % 9];
            text.push_str(&format!(" {nn}{p:03} 20020"));
        }
        text.push_str(" 21212 00020 32001 11600 18964=");
        let got = levels(&text);
        assert_eq!(got.len(), 13);
        // got[9] is the 99 level, got[10] the next 11.
        assert_eq!((got[9].0, got[10].0, got[12].0), (935.0, 927.0, 911.0));
        let d = levels("TTDD 0600/ 21824 11636 62970 22423 62571 21212 11947 17016=");
        assert_eq!(d, [(63.6, None), (42.3, None)]);
    }

    #[test]
    fn parts_are_split_at_ends_headings_and_markers() {
        let text = "USAK19 PABR 060000\nMANBRW\n70026 TTAA 56001 70026\n99031 23719 07510\n\n\
                    UMAK19 PABR 060000\nTTBB 56008 70026\n00031 23719=\nPPBB 56008 70026\n90/12 07510\n\
                    TTCC 56002 70026\n70819 50583 25522\nUFAK49 PABR 060000\n";
        let m = messages(text);
        let parts: Vec<_> = m
            .iter()
            .map(|m| (m.part, m.line, m.groups.len(), m.ending))
            .collect();
        assert_eq!(
            parts,
            [
                (Some(Part::A), 3, 5, Ending::Terminated),
                (Some(Part::B), 7, 4, Ending::Terminated),
                (None, 9, 4, Ending::Unterminated),
                (Some(Part::C), 11, 5, Ending::Unterminated),
            ]
        );
        assert!(detect(text));
        assert!(detect("TTAA 0523/ 04320"));
        assert!(!detect("TTAA 0523 04320") && !detect("TTBB 05238 04320"));
    }
}
