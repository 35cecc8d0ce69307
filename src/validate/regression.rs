//! Simple linear regression with the correlation coefficient.
