//! Reading rows whose time column is ISO 8601 text allocates nothing per row: the time
//! is parsed from the line as it is, like the numbers (a counting global allocator).

#[path = "../../../tests/counting_alloc.rs"]
mod counting_alloc;

use std::sync::atomic::Ordering;

use glrmon_core::Dims;
use glrmon_input::CsvReader;
use glrmon_wire::Sample;

use counting_alloc::{ALLOCATIONS, COUNTED, Counting};

#[global_allocator]
static ALLOCATOR: Counting = Counting;

#[test]
fn iso_times_are_read_without_an_allocation_per_row() {
    let mut file = String::from("timestamp,FIC101,LI201\n");
    let offsets = ["Z", "+01:00", "", "-0230"];
    for i in 0..1000 {
        let (m, s) = (i / 60 % 60, i % 60);
        let offset = offsets[i % offsets.len()];
        file.push_str(&format!(
            "2026-11-27T08:{m:02}:{s:02}.{:03}{offset},1.{i:03},62.{i:03}\n",
            i % 1000
        ));
    }
    let dims = Dims {
        states: 1,
        inputs: 1,
        outputs: 1,
        signals: 0,
    };
    let columns = glrmon_spec::Columns {
        u: vec!["FIC101".into()],
        y: vec!["LI201".into()],
        p: vec![],
        named: true,
        ..glrmon_spec::Columns::numbered(dims)
    };
    let mut rows = CsvReader::with_columns(file.as_bytes(), dims, &columns).unwrap();
    let mut sample = Sample::default();
    // The first rows, one of each length, size the line buffer and the sample.
    for _ in 0..offsets.len() {
        rows.next_into(&mut sample).unwrap().unwrap();
    }
    let mut read = offsets.len();
    let mut last = sample.t.unwrap();
    COUNTED.with(|c| c.set(true));
    while let Some(row) = rows.next_into(&mut sample) {
        let t = row.map(|()| sample.t);
        COUNTED.with(|c| c.set(false));
        let t = t.unwrap().unwrap();
        assert!(t.is_finite() && t != last);
        COUNTED.with(|c| c.set(true));
        last = t;
        read += 1;
    }
    COUNTED.with(|c| c.set(false));
    let allocations = ALLOCATIONS.load(Ordering::Relaxed);
    assert_eq!(read, 1000);
    assert!(rows.naive_times());
    assert_eq!(allocations, 0, "{allocations} allocations for 996 rows");
    // The count works: a message of a bad row is an allocation.
    let mut bad = CsvReader::with_columns(
        "timestamp,FIC101,LI201\n2026-11-27T25:00:00Z,1,2\n".as_bytes(),
        dims,
        &columns,
    )
    .unwrap();
    COUNTED.with(|c| c.set(true));
    let row = bad.next_into(&mut sample);
    COUNTED.with(|c| c.set(false));
    assert!(matches!(row, Some(Err(_))));
    assert!(ALLOCATIONS.load(Ordering::Relaxed) > 0);
}
