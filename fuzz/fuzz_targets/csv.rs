//! Sample CSV files (numbered or named columns) and identification tables: any bytes
//! give rows, bad rows or a header error, never a panic.
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
    };
    for columns in [Columns::numbered(dims), named] {
        if let Ok(mut rows) = CsvReader::with_columns(data, dims, &columns) {
            let mut sample = Sample::default();
            while rows.next_into(&mut sample).is_some() {}
        }
    }
    let path = std::env::temp_dir().join(format!("glrmon-fuzz-table-{}.csv", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        let _ = glrmon_input::read_table(&path, None);
    }
});
