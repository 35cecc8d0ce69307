//! The files in `examples/` stay what the README says they are.

use robocal::domain::ParameterSetDoc;
use robocal::kinematics::thesis::{irb120_table_5_1, trical_tool};

#[test]
fn example_parameter_set_is_table_5_1() {
    let doc = ParameterSetDoc::from_json(include_str!("../../examples/irb120_table_5_1.json")).unwrap();
    let want = irb120_table_5_1(trical_tool());
    assert_eq!(doc.set.model, want.model);
    assert_eq!(doc.set.tool, want.tool);
    for (i, p) in want.layout.params().iter().enumerate() {
        assert!((doc.set.values[i] - want.values[i]).abs() < 1e-12, "{p} value");
        assert!((doc.set.nominal[i] - want.nominal[i]).abs() < 1e-12, "{p} nominal");
    }
}
