//! Browser origins allowed to call the API from a web page (CORS), checked once at start-up.
//!
//! An origin is what a browser sends in its `Origin` header: `scheme://host[:port]`, nothing
//! after it. The browser sends the scheme and host in lower case and leaves out the scheme's
//! default port, so the configured origins are brought to that form here and compared exactly.

use std::net::Ipv6Addr;

use super::DomainError;

/// Which origins may call the API from a page. Off by default: no CORS header is sent and a
/// browser keeps other sites' pages from reading the answers.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum CorsOrigins {
    #[default]
    Off,
    /// `*`: any origin. Credentials (cookies) are never allowed; the API's bearer tokens travel
    /// in the `Authorization` header, which is allowed explicitly.
    Any,
    /// These origins only.
    List(Vec<Origin>),
}

/// One origin in the form a browser sends it (`https://dash.example.com`, `http://127.0.0.1:3000`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Origin(String);

impl Origin {
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Parse `scheme://host[:port]`: the scheme and host lower-cased, the scheme's default port
    /// (http 80, https 443) dropped; a path (even a lone `/`), query, user or wildcard refused.
    pub fn parse(text: &str) -> Result<Origin, String> {
        let form = "an origin is scheme://host[:port], e.g. https://dash.example.com or http://127.0.0.1:3000";
        let bad = |why: &str| format!("'{text}' is not an origin: {why} ({form})");
        let (scheme, rest) = text.split_once("://").ok_or_else(|| bad("no scheme://"))?;
        let scheme = scheme.to_ascii_lowercase();
        let scheme_ok = scheme.starts_with(|c: char| c.is_ascii_alphabetic())
            && scheme.chars().all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c));
        if !scheme_ok {
            return Err(bad("the scheme is not a URL scheme"));
        }
        if let Some(i) = rest.find(['/', '?', '#']) {
            return Err(bad(if &rest[i..] == "/" { "no trailing slash" } else { "no path, query or fragment" }));
        }
        if rest.contains('@') {
            return Err(bad("no user name or password"));
        }
        let (host, port) = if let Some(v6) = rest.strip_prefix('[') {
            let (addr, after) = v6.split_once(']').ok_or_else(|| bad("an IPv6 address needs its closing ]"))?;
            addr.parse::<Ipv6Addr>().map_err(|_| bad("not an IPv6 address between [ ]"))?;
            let port = match after {
                "" => None,
                p => Some(p.strip_prefix(':').ok_or_else(|| bad("only :port may follow the host"))?),
            };
            (format!("[{}]", addr.to_ascii_lowercase()), port)
        } else {
            let (host, port) = match rest.rsplit_once(':') {
                Some((h, p)) => (h, Some(p)),
                None => (rest, None),
            };
            let host_ok = !host.is_empty()
                && host.split('.').all(|label| {
                    !label.is_empty() && label.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
                });
            if !host_ok {
                return Err(bad(if host.contains('*') {
                    "no wildcards in a host (give each origin, or * alone for any)"
                } else {
                    "the host is not a host name or IP address (international names in their xn-- form)"
                }));
            }
            (host.to_ascii_lowercase(), port)
        };
        let port = match port {
            None => None,
            Some(p) => {
                let n = p
                    .parse::<u16>()
                    .ok()
                    .filter(|n| *n > 0 && p.chars().all(|c| c.is_ascii_digit()))
                    .ok_or_else(|| bad("the port is not a number from 1 to 65535"))?;
                let default = matches!((scheme.as_str(), n), ("http", 80) | ("https", 443));
                (!default).then_some(n)
            }
        };
        Ok(Origin(match port {
            Some(p) => format!("{scheme}://{host}:{p}"),
            None => format!("{scheme}://{host}"),
        }))
    }
}

impl std::fmt::Display for CorsOrigins {
    /// `off`, `*`, or the origins separated by commas (the form `--cors-origin` takes).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CorsOrigins::Off => f.write_str("off"),
            CorsOrigins::Any => f.write_str("*"),
            CorsOrigins::List(l) => f.write_str(&l.iter().map(Origin::as_str).collect::<Vec<_>>().join(",")),
        }
    }
}

impl CorsOrigins {
    /// From the values of a repeatable option, each of which may hold several comma-separated
    /// origins; `*` alone allows any. Nothing given (or only empty values): off. The error's path
    /// is `field`.
    pub fn parse<S: AsRef<str>>(values: &[S], field: &str) -> Result<CorsOrigins, DomainError> {
        let items: Vec<&str> =
            values.iter().flat_map(|v| v.as_ref().split(',')).map(str::trim).filter(|s| !s.is_empty()).collect();
        if items.is_empty() {
            return Ok(CorsOrigins::Off);
        }
        if items.contains(&"*") {
            return if items.len() == 1 {
                Ok(CorsOrigins::Any)
            } else {
                Err(DomainError::new(field, "* allows every origin: give it alone, or list the origins"))
            };
        }
        let mut list: Vec<Origin> = Vec::with_capacity(items.len());
        for item in items {
            if item.eq_ignore_ascii_case("null") {
                return Err(DomainError::new(
                    field,
                    "'null' is the origin of sandboxed and file:// pages, which any page can claim: it cannot be allowed",
                ));
            }
            let o = Origin::parse(item).map_err(|reason| DomainError::new(field, reason))?;
            if !list.contains(&o) {
                list.push(o);
            }
        }
        Ok(CorsOrigins::List(list))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(s: &str) -> Result<String, String> {
        Origin::parse(s).map(|o| o.0)
    }

    #[test]
    fn origins_are_brought_to_the_form_a_browser_sends() {
        assert_eq!(one("https://dash.example.com").unwrap(), "https://dash.example.com");
        assert_eq!(one("HTTPS://Dash.Example.COM:443").unwrap(), "https://dash.example.com");
        assert_eq!(one("http://localhost:80").unwrap(), "http://localhost");
        assert_eq!(one("http://127.0.0.1:3000").unwrap(), "http://127.0.0.1:3000");
        assert_eq!(
            one("https://127.0.0.1:80").unwrap(),
            "https://127.0.0.1:80",
            "80 is the default port of http, not of https"
        );
        assert_eq!(one("http://[::1]:8080").unwrap(), "http://[::1]:8080");
        assert_eq!(one("http://[FE80::1]").unwrap(), "http://[fe80::1]");
        assert_eq!(one("tauri://localhost").unwrap(), "tauri://localhost");
        assert_eq!(one("https://xn--bcher-kva.example").unwrap(), "https://xn--bcher-kva.example");
    }

    #[test]
    fn what_is_not_an_origin_is_refused_saying_why() {
        for (text, why) in [
            ("dash.example.com", "no scheme://"),
            ("https://dash.example.com/", "no trailing slash"),
            ("https://dash.example.com/app", "no path"),
            ("https://dash.example.com?x=1", "no path"),
            ("https://user@dash.example.com", "no user"),
            ("https://*.example.com", "no wildcards"),
            ("https://", "not a host"),
            ("https://a..b", "not a host"),
            ("https://bücher.example", "xn--"),
            ("https://dash.example.com:0", "port"),
            ("https://dash.example.com:65536", "port"),
            ("https://dash.example.com:+80", "port"),
            ("https://dash.example.com:", "port"),
            ("http://[::1", "closing ]"),
            ("http://[nope]", "IPv6"),
            ("http://[::1]x", "only :port"),
            ("1http://x", "scheme"),
        ] {
            let e = one(text).unwrap_err();
            assert!(e.contains(why) && e.contains(text), "{text}: {e}");
        }
    }

    #[test]
    fn a_list_from_repeated_and_comma_separated_values() {
        let f = "--cors-origin";
        assert_eq!(CorsOrigins::parse::<&str>(&[], f).unwrap(), CorsOrigins::Off);
        assert_eq!(CorsOrigins::parse(&["", " , "], f).unwrap(), CorsOrigins::Off);
        assert_eq!(CorsOrigins::parse(&[" * "], f).unwrap(), CorsOrigins::Any);
        let CorsOrigins::List(l) =
            CorsOrigins::parse(&["https://a.example, http://localhost:3000", "https://A.example:443"], f).unwrap()
        else {
            panic!("a list")
        };
        assert_eq!(l.iter().map(Origin::as_str).collect::<Vec<_>>(), ["https://a.example", "http://localhost:3000"]);
        assert_eq!(CorsOrigins::List(l).to_string(), "https://a.example,http://localhost:3000");
        assert_eq!((CorsOrigins::Off.to_string(), CorsOrigins::Any.to_string()), ("off".into(), "*".into()));
        let e = CorsOrigins::parse(&["*", "https://a.example"], f).unwrap_err();
        assert_eq!(e.path, f);
        assert!(e.reason.contains("alone"), "{e}");
        let e = CorsOrigins::parse(&["null"], f).unwrap_err();
        assert!(e.reason.contains("cannot be allowed"), "{e}");
        let e = CorsOrigins::parse(&["https://ok.example,https://bad.example/"], f).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!(
                "{f}: 'https://bad.example/' is not an origin: no trailing slash (an origin is scheme://host[:port], e.g. https://dash.example.com or http://127.0.0.1:3000)"
            )
        );
    }
}
