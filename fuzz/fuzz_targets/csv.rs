//! Sample CSV files (numbered or named columns) and identification tables: any bytes
//! give rows, bad rows or a header error, never a panic. The bytes are read as a whole
//! file and, after a header whose time column holds ISO 8601 text (`timestamp`), as rows:
//! any time is seconds since the epoch that are finite, or a bad row.
#![no_main]

use glrmon_core::Dims;
use glrmon_input::CsvReader;
use glrmon_spec::Columns;
use glrmon_wire::Sample;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dims = Dims {
        states: 1,
        inputs: 1,
        outputs: 2,
        signals: 0,
    };
    let named = Columns {
        u: vec!["FI1".into()],
        y: vec!["y0".into(), "TI 2".into()],
        p: vec![],
        named: true,
        ..Columns::numbered(dims)
    };
    let mut timed = b"timestamp,FI1,y0,TI 2\n".to_vec();
    timed.extend_from_slice(data);
    for columns in [Columns::numbered(dims), named] {
        for file in [data, &timed] {
            if let Ok(mut rows) = CsvReader::with_columns(file, dims, &columns) {
                let mut sample = Sample::default();
                while let Some(row) = rows.next_into(&mut sample) {
                    if row.is_ok() {
                        assert!(sample.t.is_none_or(f64::is_finite));
                    }
                }
            }
        }
    }
    let path = std::env::temp_dir().join(format!("glrmon-fuzz-table-{}.csv", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        let _ = glrmon_input::read_table(&path, None);
    }
});
