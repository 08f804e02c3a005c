//! Where a remote object's requests go: a plain `http(s)://` URL as it is, or an
//! `s3://BUCKET/KEY` object through a freshly presigned `GET` for each request (AWS Signature
//! V4 by `rusty-s3`, which does no I/O), from the credentials and region in the usual
//! environment variables.

use std::path::Path;
use std::time::Duration;

use crate::error::{Error, Result};

/// Where the requests go.
pub(super) enum Target {
    /// A plain URL.
    Http(String),
    /// An object in an S3 bucket: each request gets a freshly presigned URL.
    S3 {
        bucket: Box<rusty_s3::Bucket>,
        key: String,
        credentials: Option<rusty_s3::Credentials>,
    },
}

impl Target {
    pub(super) fn parse(url: &str) -> Result<Target> {
        let Some(rest) = url.strip_prefix("s3://") else {
            return Ok(Target::Http(url.to_string()));
        };
        let bad = |why: &str| Error::input(Path::new(url), why.to_string());
        let (bucket, key) = rest
            .split_once('/')
            .filter(|(b, k)| !b.is_empty() && !k.is_empty())
            .ok_or_else(|| bad("an S3 URL is s3://BUCKET/KEY"))?;
        let var = |name: &str| std::env::var(name).ok().filter(|v| !v.is_empty());
        let region = var("AWS_REGION")
            .or_else(|| var("AWS_DEFAULT_REGION"))
            .unwrap_or_else(|| "us-east-1".into());
        let (endpoint, style) = match var("AWS_ENDPOINT_URL") {
            Some(e) => (e, rusty_s3::UrlStyle::Path),
            None => (
                format!("https://s3.{region}.amazonaws.com"),
                rusty_s3::UrlStyle::VirtualHost,
            ),
        };
        let endpoint = endpoint
            .parse()
            .map_err(|e| bad(&format!("AWS_ENDPOINT_URL {endpoint:?}: {e}")))?;
        let bucket = rusty_s3::Bucket::new(endpoint, style, bucket.to_string(), region)
            .map_err(|e| bad(&format!("bucket {bucket:?}: {e}")))?;
        Ok(Target::S3 {
            bucket: Box::new(bucket),
            key: key.to_string(),
            credentials: rusty_s3::Credentials::from_env(),
        })
    }

    /// The URL of the next request.
    pub(super) fn request_url(&self) -> String {
        match self {
            Target::Http(url) => url.clone(),
            Target::S3 {
                bucket,
                key,
                credentials,
            } => {
                use rusty_s3::S3Action;
                bucket
                    .get_object(credentials.as_ref(), key)
                    .sign(Duration::from_secs(900))
                    .to_string()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn s3_urls_need_a_bucket_and_a_key() {
        assert!(Target::parse("s3://bucket").is_err());
        assert!(Target::parse("s3:///key").is_err());
        assert!(Target::parse("s3://bucket/").is_err());
        assert!(Target::parse("s3://bucket/a/b.fmrh").is_ok());
        assert!(matches!(
            Target::parse("http://h/x"),
            Ok(Target::Http(u)) if u == "http://h/x"
        ));
    }
}
