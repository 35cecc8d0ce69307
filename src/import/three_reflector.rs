//! Three-reflector format: a joints file plus one positions file per reflector.
