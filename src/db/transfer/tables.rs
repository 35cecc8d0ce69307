//! The tables `robocal migrate` copies: their columns, the copy order (parents first, a nullable
//! cycle deferred) and the per-table verification.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

use super::PgType;

/// A target column.
#[derive(Clone, Debug)]
pub struct Column {
    pub name: String,
    pub ty: PgType,
    pub nullable: bool,
}

/// One table's copy plan.
#[derive(Clone, Debug)]
pub struct TablePlan {
    pub name: String,
    pub columns: Vec<Column>,
    /// Indexes into `columns` of the primary key, in key order.
    pub key: Vec<usize>,
    /// Indexes into `columns` written NULL with the row and set after every table is copied
    /// (nullable foreign keys that close a cycle).
    pub deferred: Vec<usize>,
}

/// A foreign key between two target tables (child columns → parent).
#[derive(Clone, Debug)]
pub struct ForeignKey {
    pub child: String,
    pub columns: Vec<String>,
    pub parent: String,
}

/// The tables in copy order, and the (table, column) pairs written NULL first.
pub type TableOrder = (Vec<String>, BTreeSet<(String, String)>);

/// The tables in an order where every parent comes before its children (alphabetical among
/// equals), and the (table, column) pairs deferred to break cycles: when no table is left whose
/// parents are all placed, a foreign key on a cycle among the remaining tables whose columns are
/// all nullable is deferred (one whose table then waits on nothing else first, then by child and
/// parent name). A cycle through NOT NULL columns only
/// cannot be copied row by row and is an error.
pub fn order_tables(tables: &BTreeMap<String, Vec<Column>>, fks: &[ForeignKey]) -> Result<TableOrder, String> {
    let mut edges: Vec<&ForeignKey> = fks.iter().filter(|f| tables.contains_key(&f.parent)).collect();
    let mut placed: Vec<String> = Vec::new();
    let mut deferred = BTreeSet::new();
    let mut left: BTreeSet<&String> = tables.keys().collect();
    while !left.is_empty() {
        let ready = left.iter().find(|t| !edges.iter().any(|f| &&f.child == *t && left.contains(&f.parent))).copied();
        if let Some(t) = ready {
            placed.push(t.clone());
            left.remove(t);
            continue;
        }
        let nullable = |f: &ForeignKey| {
            f.columns.iter().all(|c| tables[&f.child].iter().any(|col| &col.name == c && col.nullable))
        };
        // Whether `from` depends, through the remaining tables' keys, on `to`.
        let depends = |from: &String, to: &String| {
            let (mut seen, mut stack) = (BTreeSet::new(), vec![from]);
            while let Some(t) = stack.pop() {
                if t == to {
                    return true;
                }
                if seen.insert(t) {
                    stack.extend(edges.iter().filter(|f| &f.child == t && left.contains(&f.parent)).map(|f| &f.parent));
                }
            }
            false
        };
        // A key on a cycle: its parent depends on its child.
        let mut candidates: Vec<usize> = (0..edges.len())
            .filter(|&i| {
                left.contains(&edges[i].child)
                    && left.contains(&edges[i].parent)
                    && nullable(edges[i])
                    && depends(&edges[i].parent, &edges[i].child)
            })
            .collect();
        // Fewest deferrals: first a key whose child then waits on nothing else.
        let waits = |t: &String| edges.iter().filter(|f| &f.child == t && left.contains(&f.parent)).count();
        candidates.sort_by_key(|&i| (waits(&edges[i].child), &edges[i].child, &edges[i].parent));
        let Some(&i) = candidates.first() else {
            let names: Vec<&str> = left.iter().map(|s| s.as_str()).collect();
            return Err(format!("a foreign-key cycle through NOT NULL columns among {}", names.join(", ")));
        };
        let f = edges.remove(i);
        for c in &f.columns {
            deferred.insert((f.child.clone(), c.clone()));
        }
    }
    Ok((placed, deferred))
}

/// Per table: rows on each side and whether the checksums match.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TableCheck {
    pub table: String,
    pub source_rows: u64,
    pub target_rows: u64,
    pub source_sha256: String,
    pub target_sha256: String,
}

impl TableCheck {
    pub fn matches(&self) -> bool {
        self.source_rows == self.target_rows && self.source_sha256 == self.target_sha256
    }
}

/// The verification of a migration, table by table (in copy order).
#[derive(Clone, Debug)]
pub struct Verification {
    pub tables: Vec<TableCheck>,
}

impl Verification {
    pub fn ok(&self) -> bool {
        self.tables.iter().all(TableCheck::matches)
    }

    /// The tables that differ.
    pub fn mismatched(&self) -> Vec<&str> {
        self.tables.iter().filter(|t| !t.matches()).map(|t| t.table.as_str()).collect()
    }

    /// A table for people: rows on each side, the checksum verdict, its first 16 hex digits.
    pub fn table(&self) -> String {
        let mut s =
            format!("{:<28} {:>12} {:>12}  {:<9} {}\n", "table", "source rows", "target rows", "checksum", "sha256");
        for t in &self.tables {
            let verdict = if t.matches() { "match" } else { "MISMATCH" };
            let sha = if t.matches() {
                t.source_sha256[..16].to_string()
            } else {
                format!("{} ≠ {}", &t.source_sha256[..16], &t.target_sha256[..16])
            };
            let _ = writeln!(s, "{:<28} {:>12} {:>12}  {verdict:<9} {sha}", t.table, t.source_rows, t.target_rows);
        }
        s.pop();
        s
    }
}
