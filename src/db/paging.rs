//! One page of a list and the list's length from one query: the page's `SELECT` adds
//! `COUNT(*) OVER () AS total_rows`, which SQLite computes over the whole filtered list before
//! `LIMIT`/`OFFSET` cut the page, so every row of the page carries the list's length. A page past
//! the end has no row to carry it: only then is the list counted on its own.

use std::future::Future;

use sqlx::any::{AnyArguments, AnyRow};
use sqlx::query::QueryAs;
use sqlx::{Any, FromRow, Row};

use super::Pool;

/// A row of a page query and the length of the whole list beside it (the query's `total_rows`
/// column, `COUNT(*) OVER () AS total_rows`).
#[derive(Clone, Debug, PartialEq)]
pub struct Counted<T> {
    pub row: T,
    pub total: i64,
}

impl<'r, T: FromRow<'r, AnyRow>> FromRow<'r, AnyRow> for Counted<T> {
    fn from_row(row: &'r AnyRow) -> Result<Self, sqlx::Error> {
        Ok(Counted { row: T::from_row(row)?, total: row.try_get("total_rows")? })
    }
}

/// A page of a list: its rows, and how many rows the whole list has (its filters applied).
#[derive(Clone, Debug, PartialEq)]
pub struct Page<T> {
    pub items: Vec<T>,
    pub total: i64,
}

impl<T> Page<T> {
    /// The page from the rows of its query fetched at `offset`. `count` (the list's length on its
    /// own) runs only for an empty page past the start, which no row tells the length of; an
    /// empty first page is an empty list.
    pub async fn of(
        rows: Vec<Counted<T>>,
        offset: i64,
        count: impl Future<Output = Result<i64, sqlx::Error>>,
    ) -> Result<Page<T>, sqlx::Error> {
        let total = match rows.first() {
            Some(r) => r.total,
            None if offset == 0 => 0,
            None => count.await?,
        };
        Ok(Page { items: rows.into_iter().map(|r| r.row).collect(), total })
    }
}

/// The page `offset..offset + limit` of a list: `query` is the list's `SELECT` with
/// `COUNT(*) OVER () AS total_rows` among its columns, ending in `LIMIT ? OFFSET ?` (bound here,
/// after the parameters the query has bound already); `count` is the list's length on its own
/// (see [`Page::of`]).
pub async fn fetch<'q, T>(
    db: &Pool,
    query: QueryAs<'q, Any, Counted<T>, AnyArguments>,
    offset: i64,
    limit: i64,
    count: impl Future<Output = Result<i64, sqlx::Error>>,
) -> Result<Page<T>, sqlx::Error>
where
    T: Send + Unpin + for<'r> FromRow<'r, AnyRow>,
{
    let rows = query.bind(limit).bind(offset).fetch_all(db).await?;
    Page::of(rows, offset, count).await
}

#[cfg(test)]
mod tests {
    use super::*;

    async fn numbers(n: i64) -> crate::db::Pool {
        let db = crate::db::connect_memory().await.unwrap();
        sqlx::query("CREATE TABLE t (k INTEGER, odd INTEGER)").execute(&db).await.unwrap();
        for k in 0..n {
            sqlx::query("INSERT INTO t VALUES ($1, $2)").bind(k).bind(k % 2).execute(&db).await.unwrap();
        }
        db
    }

    async fn page(db: &crate::db::Pool, odd: i64, offset: i64, limit: i64) -> Page<(i64,)> {
        let query = sqlx::query_as(
            "SELECT k, COUNT(*) OVER () AS total_rows FROM t WHERE odd = $1 ORDER BY k DESC LIMIT $2 OFFSET $3",
        )
        .bind(odd);
        let count = sqlx::query_scalar("SELECT COUNT(*) FROM t WHERE odd = $1").bind(odd).fetch_one(db);
        fetch(db, query, offset, limit, count).await.unwrap()
    }

    #[tokio::test]
    async fn every_page_carries_the_filtered_lists_length() {
        let db = numbers(11).await;
        // The odd numbers below 11: 9 7 5 3 1 — five of them, whatever the page.
        assert_eq!(page(&db, 1, 0, 2).await, Page { items: vec![(9,), (7,)], total: 5 });
        assert_eq!(page(&db, 1, 4, 2).await, Page { items: vec![(1,)], total: 5 });
        // Past the end no row carries the length: the count tells it.
        assert_eq!(page(&db, 1, 5, 2).await, Page { items: vec![], total: 5 });
        assert_eq!(page(&db, 1, 100, 2).await, Page { items: vec![], total: 5 });
        // The even ones: 10 8 6 4 2 0.
        assert_eq!(page(&db, 0, 3, 100).await, Page { items: vec![(4,), (2,), (0,)], total: 6 });
    }

    #[tokio::test]
    async fn an_empty_first_page_is_an_empty_list_without_counting() {
        let db = numbers(0).await;
        let rows: Vec<Counted<(i64,)>> =
            sqlx::query_as("SELECT k, COUNT(*) OVER () AS total_rows FROM t LIMIT 10").fetch_all(&db).await.unwrap();
        async fn never() -> Result<i64, sqlx::Error> {
            unreachable!("an empty first page is not counted")
        }
        assert_eq!(Page::of(rows, 0, never()).await.unwrap(), Page { items: vec![], total: 0 });
    }
}
