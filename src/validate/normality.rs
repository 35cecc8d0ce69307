//! Shapiro–Wilk normality test with Royston's p-value.
