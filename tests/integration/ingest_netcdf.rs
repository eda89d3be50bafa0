//! Stage 1 — ingest of netCDF soundings (`tests/data/soundings/netcdf/`, provenance in its
//! README): an ARM `sondewnpn` b1 file and a GRUAN RS92 GDP file. Without the cargo feature
//! `netcdf` such a file is refused with a message saying how to rebuild; with it, the files read,
//! checked against values read from the files independently of ghostship (Python `netCDF4`
//! 1.7.5, `Dataset(f)[var][i]`, printed and copied here by hand), and crafted files check fill
//! values, units and errors.

use std::io::Write;
use std::path::PathBuf;

use ghostship::sounding::{ReadOptions, is_netcdf, read_sounding, sounding_times};

use crate::support::data::sounding;

fn arm_file() -> PathBuf {
    sounding("netcdf/sgpsondewnpnC1.b1.20190101.053200.cdf")
}

fn gruan_file() -> PathBuf {
    sounding("netcdf/PAY-RS-01_2_RS92-GDP_002_20171024T120000_1-000-001.nc")
}

/// A temporary file holding `bytes`.
fn temp_file(bytes: &[u8]) -> tempfile::NamedTempFile {
    let mut f = tempfile::NamedTempFile::new().unwrap();
    f.write_all(bytes).unwrap();
    f.flush().unwrap();
    f
}

#[test]
fn the_samples_start_with_a_netcdf_magic_number() {
    // Classic netCDF starts with "CDF" and version byte 1 (netCDF format specification).
    for path in [arm_file(), gruan_file()] {
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..4], b"CDF\x01", "{}", path.display());
        assert!(is_netcdf(&bytes));
    }
    assert!(!is_netcdf(b"CDF\x03"));
    assert!(!is_netcdf(b"pressure_hpa,height_m,temperature_c\n"));
}

#[test]
fn sounding_times_of_a_netcdf_file_is_none() {
    assert_eq!(sounding_times(&arm_file()).unwrap(), None);
}

#[cfg(not(feature = "netcdf"))]
mod without_feature {
    use super::*;
    use crate::support::cli::fails;
    use ghostship::sounding::SoundingError;

    /// Files with each netCDF magic number: the two real samples, a netCDF-4 (HDF5) header and a
    /// 64-bit-offset header, each followed by bytes that are not UTF-8.
    fn magic_files() -> Vec<(String, tempfile::NamedTempFile)> {
        let mut out = Vec::new();
        for path in [arm_file(), gruan_file()] {
            out.push((
                path.display().to_string(),
                temp_file(&std::fs::read(&path).unwrap()),
            ));
        }
        for (name, magic) in [
            ("netCDF-4 / HDF5", &b"\x89HDF\r\n\x1a\n"[..]),
            ("64-bit offset", &b"CDF\x02"[..]),
        ] {
            let mut bytes = magic.to_vec();
            bytes.extend_from_slice(&[0xff, 0xfe, 0x00, 0x80]);
            out.push((name.to_string(), temp_file(&bytes)));
        }
        out
    }

    #[test]
    fn a_netcdf_file_is_refused_with_how_to_rebuild() {
        for (name, file) in magic_files() {
            let e = read_sounding(file.path(), &ReadOptions::default()).unwrap_err();
            assert!(
                matches!(e, SoundingError::NetcdfNotBuilt { .. }),
                "{name}: {e}"
            );
            let message = e.to_string();
            assert!(message.starts_with(&format!("{}: ", file.path().display())));
            assert!(
                message
                    .contains("is a netCDF file; this ghostship was built without netCDF support")
                    && message.contains("cargo build --release --features netcdf")
                    && message.contains("libnetcdf-dev"),
                "{name}: {message}"
            );
            assert!(!message.contains("UTF-8"), "{name}: {message}");
        }
    }

    #[test]
    fn a_gzipped_netcdf_file_is_refused_the_same_way() {
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        gz.write_all(&std::fs::read(arm_file()).unwrap()).unwrap();
        let file = temp_file(&gz.finish().unwrap());
        let e = read_sounding(file.path(), &ReadOptions::default()).unwrap_err();
        assert!(matches!(e, SoundingError::NetcdfNotBuilt { .. }), "{e}");
    }

    #[test]
    fn the_cli_says_how_to_rebuild() {
        let path = arm_file();
        let r = fails(&["profile", path.to_str().unwrap()]);
        assert!(
            r.stderr.contains("--features netcdf") && !r.stderr.contains("UTF-8"),
            "{}",
            r.stderr
        );
    }
}

#[cfg(feature = "netcdf")]
mod with_feature {
    use super::*;
    use std::path::Path;

    use ghostship::sounding::{HeightSource, Level, Sounding, SoundingFormat};
    use ghostship::units::saturation_vapour_pressure_pa;

    fn read(path: &Path) -> Sounding {
        read_sounding(path, &ReadOptions::default())
            .unwrap_or_else(|e| panic!("{} failed to ingest: {e}", path.display()))
    }

    /// The level read from record `record` (1-based).
    fn record(s: &Sounding, record: usize) -> &Level {
        s.levels
            .iter()
            .find(|l| l.line == record)
            .unwrap_or_else(|| panic!("no level from record {record}"))
    }

    /// Checks a level against the file's values: pressure (hPa), temperature (°C), height (m),
    /// relative humidity (%). The f32 values of the file are compared to 1e-3 of their unit.
    fn check(level: &Level, pressure_hpa: f64, temperature_c: f64, height_m: f64, rh_pct: f64) {
        let close = |a: f64, b: f64, what: &str| {
            assert!(
                (a - b).abs() < 1e-3,
                "record {}: {what} {a} vs {b}",
                level.line
            )
        };
        close(
            level.pressure_pa.unwrap() / 100.0,
            pressure_hpa,
            "pressure hPa",
        );
        close(
            level.temperature_k - 273.15,
            temperature_c,
            "temperature °C",
        );
        close(level.height_m, height_m, "height m");
        let e_pa = level.vapour_pressure_pa.unwrap();
        let rh = 100.0 * e_pa / saturation_vapour_pressure_pa(level.temperature_k);
        close(rh, rh_pct, "relative humidity %");
        assert_eq!(level.height_source, HeightSource::Measured);
    }

    #[test]
    fn arm_sondewnpn_reads_with_its_levels_and_metadata() {
        let s = read(&arm_file());
        assert_eq!(s.format, SoundingFormat::Netcdf);
        // 4176 records along `time`; none missing, heights strictly increasing, pressure never
        // increasing (checked in Python with numpy.diff): every record is a level.
        assert_eq!(s.levels.len(), 4176);
        assert!(s.warnings.is_empty(), "{:?}", s.warnings);
        // pres, tdry, alt, rh of records 1, 101, 1001 and 4176 (Python netCDF4).
        check(
            s.surface(),
            986.989990234375,
            -3.299999952316284,
            314.79998779296875,
            74.0,
        );
        assert_eq!(s.surface().line, 1);
        check(
            record(&s, 101),
            922.5900268554688,
            -8.760000228881836,
            843.0,
            96.69000244140625,
        );
        check(
            record(&s, 1001),
            452.6300048828125,
            -22.950000762939453,
            6345.0,
            19.389999389648438,
        );
        check(
            record(&s, 4176),
            25.829999923706055,
            -64.1500015258789,
            24569.5,
            1.1299999952316284,
        );
        // The file's own dewpoint (dp = -7.27 °C at record 1) gives nearly the same vapour
        // pressure as its relative humidity: the two are consistent to 2 %.
        let from_dp = saturation_vapour_pressure_pa(273.15 - 7.269999980926514);
        let e = s.surface().vapour_pressure_pa.unwrap();
        assert!((e / from_dp - 1.0).abs() < 0.02, "{e} vs {from_dp}");
        let m = &s.metadata;
        assert_eq!(m["product"], "ARM sondewnpn-b1-2.1");
        assert_eq!(m["station"], "sgp C1: Lamont, Oklahoma");
        // lat[0], lon[0] = 36.61000061035156, -97.48999786376953.
        assert_eq!(
            (m["latitude"].as_str(), m["longitude"].as_str()),
            ("36.61", "-97.49")
        );
        assert_eq!(s.metadata_number("station_elevation_m"), Some(314.8));
        // base_time 1546300800 (2019-01-01 00:00 UTC) + time_offset[0] 19920 s = 05:32:00.
        assert_eq!(m["launch_time_utc"], "2019-01-01 05:32:00 UTC");
        assert_eq!(m["sonde_serial_number"], "P3120796");
    }

    #[test]
    fn gruan_rs92_gdp_reads_with_its_levels_and_metadata() {
        let s = read(&gruan_file());
        assert_eq!(s.format, SoundingFormat::Netcdf);
        // 5643 records, no NaN in press/temp/alt/rh, alt strictly increasing (Python).
        assert_eq!(s.levels.len(), 5643);
        // press (hPa), temp (K → °C), alt (m), rh (fraction → %) of records 1, 101, 1001, 5643.
        check(
            s.surface(),
            969.9955444335938,
            284.7845458984375 - 273.15,
            486.7266845703125,
            64.22669291496277,
        );
        check(
            record(&s, 101),
            906.6748657226562,
            281.4369201660156 - 273.15,
            1046.9405517578125,
            66.778165102005,
        );
        check(
            record(&s, 1001),
            442.45745849609375,
            252.50979614257812 - 273.15,
            6710.94384765625,
            52.37366557121277,
        );
        check(
            record(&s, 5643),
            5.886125087738037,
            222.7261505126953 - 273.15,
            34211.8828125,
            0.9618962183594704,
        );
        let m = &s.metadata;
        assert_eq!(m["product"], "GRUAN RS92-GDP version 2");
        assert_eq!(m["station"], "Payerne (PAY)");
        assert_eq!(m["wmo_id"], "06610");
        // g.MeasuringSystem.Latitude "46.81 °", Longitude "6.95 °", Altitude "491.0 m".
        assert_eq!(
            (m["latitude"].as_str(), m["longitude"].as_str()),
            ("46.81", "6.95")
        );
        assert_eq!(s.metadata_number("station_elevation_m"), Some(491.0));
        // g.Ascent.StartTime "2017-10-24T11:06:04", StandardTime "2017-10-24T12:00:00".
        assert_eq!(m["launch_time_utc"], "2017-10-24 11:06:04 UTC");
        assert_eq!(m["nominal_time_utc"], "2017-10-24 12");
        assert_eq!(m["instrument"], "RS92-SGP");
    }

    #[test]
    fn a_gzipped_sample_reads_like_the_plain_file() {
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        gz.write_all(&std::fs::read(gruan_file()).unwrap()).unwrap();
        let file = temp_file(&gz.finish().unwrap());
        let packed = read(file.path());
        assert_eq!(packed.levels, read(&gruan_file()).levels);
        assert!(packed.metadata.contains_key("packed_as"));
    }

    #[test]
    fn a_sounding_time_is_refused_for_a_netcdf_file() {
        let e = read_sounding(&arm_file(), &ReadOptions::with_time("2019-01-01 06")).unwrap_err();
        assert!(e.to_string().contains("holds one sounding"), "{e}");
    }

    /// One variable of a crafted file: name, units, values, and an optional missing-value
    /// attribute (name, value).
    type Var<'a> = (&'a str, &'a str, &'a [f64], Option<(&'a str, f64)>);

    /// A netCDF file (64-bit offset) with one dimension `time` and the variables `vars`.
    fn crafted(vars: &[Var]) -> tempfile::TempPath {
        crafted_as(netcdf::Options::_64BIT_OFFSET, vars)
    }

    /// A netCDF file in the format `options` with one dimension `time` and the variables `vars`.
    fn crafted_as(options: netcdf::Options, vars: &[Var]) -> tempfile::TempPath {
        let path = tempfile::NamedTempFile::new().unwrap().into_temp_path();
        let mut file = netcdf::create_with(&path, options).unwrap();
        let n = vars.iter().map(|v| v.2.len()).max().unwrap();
        file.add_dimension("time", n).unwrap();
        // Classic files define every variable before any data is written.
        for &(name, units, _, missing) in vars {
            let mut var = file.add_variable::<f64>(name, &["time"]).unwrap();
            var.put_attribute("units", units).unwrap();
            if let Some((attribute, value)) = missing {
                var.put_attribute(attribute, value).unwrap();
            }
        }
        file.enddef().unwrap();
        for &(name, _, values, _) in vars {
            let mut var = file.variable_mut(name).unwrap();
            var.put_values(values, ..).unwrap();
        }
        file.close().unwrap();
        path
    }

    #[test]
    fn fill_values_and_units_are_honoured() {
        let path = crafted(&[
            (
                "pres",
                "kPa",
                &[100.0, 95.0, 90.0, 85.0],
                Some(("_FillValue", -999.0)),
            ),
            (
                "tdry",
                "K",
                &[280.0, -999.0, 275.0, 272.0],
                Some(("_FillValue", -999.0)),
            ),
            ("alt", "km", &[0.01, 0.45, 0.9, 1.35], None),
            (
                "rh",
                "%",
                &[50.0, 60.0, -9999.0, f64::NAN],
                Some(("missing_value", -9999.0)),
            ),
            ("dp", "degC", &[-2.0, -3.0, -4.0, -5.0], None),
        ]);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..4], b"CDF\x02");
        let s = read(&path);
        // Record 2 has no temperature: skipped, with the usual warning naming it.
        let lines: Vec<usize> = s.levels.iter().map(|l| l.line).collect();
        assert_eq!(lines, [1, 3, 4]);
        assert!(
            s.warnings[0].contains("without temperature"),
            "{:?}",
            s.warnings
        );
        let l = s.surface();
        assert_eq!(l.pressure_pa, Some(100_000.0)); // 100 kPa
        assert_eq!(l.temperature_k, 280.0);
        assert!((l.height_m - 10.0).abs() < 1e-9); // 0.01 km
        let e_s = saturation_vapour_pressure_pa(280.0);
        assert!((l.vapour_pressure_pa.unwrap() - 0.5 * e_s).abs() < 1e-9);
        // Records 3 and 4: relative humidity missing (missing_value, NaN), the dewpoint is used.
        let td = |c: f64| saturation_vapour_pressure_pa(273.15 + c);
        assert_eq!(record(&s, 3).vapour_pressure_pa, Some(td(-4.0)));
        assert_eq!(record(&s, 4).vapour_pressure_pa, Some(td(-5.0)));
    }

    #[test]
    fn a_netcdf4_file_reads_from_memory() {
        let path = crafted_as(
            netcdf::Options::NETCDF4,
            &[
                ("press", "Pa", &[100_000.0, 95_000.0, 90_000.0], None),
                ("temp", "degC", &[5.0, 2.0, -1.0], None),
                ("alt", "m", &[10.0, 450.0, 900.0], None),
                ("rh", "1", &[0.5, 0.6, 0.7], None),
            ],
        );
        assert_eq!(&std::fs::read(&path).unwrap()[..8], b"\x89HDF\r\n\x1a\n");
        let s = read(&path);
        let heights: Vec<f64> = s.levels.iter().map(|l| l.height_m).collect();
        assert_eq!(heights, [10.0, 450.0, 900.0]);
        assert_eq!(s.levels[2].pressure_pa, Some(90_000.0));
        assert!((s.levels[2].temperature_k - 272.15).abs() < 1e-9);
        let e_s = saturation_vapour_pressure_pa(s.levels[2].temperature_k);
        assert!((s.levels[2].vapour_pressure_pa.unwrap() - 0.7 * e_s).abs() < 1e-9);
    }

    #[test]
    fn bad_units_unknown_products_and_bad_values_are_errors_naming_the_variable() {
        let base = |temperature_units: &str, temperature: &[f64]| {
            crafted(&[
                ("press", "hPa", &[1000.0, 950.0, 900.0], None),
                ("temp", temperature_units, temperature, None),
                ("alt", "m", &[10.0, 450.0, 900.0], None),
            ])
        };
        let file = base("F", &[50.0, 48.0, 46.0]);
        let e = read_sounding(&file, &ReadOptions::default()).unwrap_err();
        let message = e.to_string();
        assert!(
            message.contains("variable temp") && message.contains("\"F\""),
            "{message}"
        );

        // 400 K is out of range: the error names the record (as the line) and the variable.
        let file = base("K", &[280.0, 400.0, 270.0]);
        let e = read_sounding(&file, &ReadOptions::default()).unwrap_err();
        assert_eq!((e.line(), e.column()), (Some(2), Some("temp")), "{e}");

        // GRUAN product without humidity: dry levels, read fine.
        let s = read(&base("K", &[280.0, 279.0, 278.0]));
        assert_eq!(s.levels.len(), 3);
        assert!(s.levels.iter().all(|l| l.vapour_pressure_pa.is_none()));

        let file = crafted(&[("x", "m", &[1.0, 2.0, 3.0], None)]);
        let e = read_sounding(&file, &ReadOptions::default()).unwrap_err();
        let message = e.to_string();
        assert!(
            message.contains("not a known sounding product") && message.contains(" x"),
            "{message}"
        );
    }

    #[test]
    fn a_truncated_netcdf_file_is_an_error_not_a_panic() {
        let bytes = std::fs::read(arm_file()).unwrap();
        for len in [4, 100, bytes.len() / 2] {
            let file = temp_file(&bytes[..len]);
            let e = read_sounding(file.path(), &ReadOptions::default()).unwrap_err();
            assert!(
                e.to_string()
                    .starts_with(&format!("{}: ", file.path().display())),
                "{e}"
            );
        }
    }
}
