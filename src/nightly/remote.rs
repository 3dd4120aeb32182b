//! Archives and datasets on S3-compatible object storage (`s3://bucket/prefix`),
//! through the `object_store` crate (docs/nightly.md, "Object storage").
//!
//! `process` works on local folders; a remote archive or dataset is
//! mirrored into a local cache first, incrementally (an object is
//! downloaded only when its ETag changed since the last sync), and a
//! remote dataset is published after a commit: changed files are uploaded
//! and removed ones deleted, then `dataset.json` last with a conditional
//! put (If-Match on the ETag this process pulled, or If-None-Match for a
//! new dataset). If another process committed in between, the put fails
//! and nothing of ours is named by the remote `dataset.json`.

use super::NightlyError;
use object_store::aws::AmazonS3Builder;
use object_store::path::Path as ObjectPath;
use object_store::{ObjectStore, PutMode, PutOptions, PutPayload, UpdateVersion};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where an archive or a dataset lives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Location {
    Local(PathBuf),
    /// `s3://bucket/prefix` (prefix without leading or trailing `/`).
    S3 {
        bucket: String,
        prefix: String,
    },
}

impl Location {
    /// `s3://bucket[/prefix]`, or a local path.
    pub fn parse(s: &str) -> Result<Location, NightlyError> {
        let Some(rest) = s.strip_prefix("s3://") else {
            return Ok(Location::Local(PathBuf::from(s)));
        };
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        if bucket.is_empty() {
            return Err(NightlyError::Invalid(format!(
                "'{s}': no bucket (s3://bucket/prefix)"
            )));
        }
        Ok(Location::S3 {
            bucket: bucket.to_string(),
            prefix: prefix.trim_matches('/').to_string(),
        })
    }

    pub fn url(&self) -> String {
        match self {
            Location::Local(p) => p.display().to_string(),
            Location::S3 { bucket, prefix } => format!("s3://{bucket}/{prefix}"),
        }
    }

    /// Whether `other` is this remote location or lies under it (the same
    /// bucket, its prefix within this one's, part by part). Local paths are
    /// compared by `ProcessOptions::check`, on their mirrors.
    pub fn holds(&self, other: &Location) -> bool {
        match (self, other) {
            (
                Location::S3 { bucket, prefix },
                Location::S3 {
                    bucket: b,
                    prefix: p,
                },
            ) => {
                let parts = |x: &str| {
                    x.split('/')
                        .filter(|s| !s.is_empty())
                        .map(str::to_string)
                        .collect::<Vec<_>>()
                };
                bucket == b && parts(p).starts_with(&parts(prefix))
            }
            _ => false,
        }
    }

    /// The folder of the local mirror of a remote location under `cache`.
    pub fn mirror(&self, cache: &Path) -> PathBuf {
        match self {
            Location::Local(p) => p.clone(),
            Location::S3 { bucket, prefix } => {
                let mut p = cache.join("s3").join(bucket);
                for part in prefix.split('/').filter(|x| !x.is_empty()) {
                    p.push(part);
                }
                p
            }
        }
    }
}

/// How to reach the store: the `AWS_*` environment variables by default
/// (`AWS_ENDPOINT`, `AWS_REGION`, `AWS_ACCESS_KEY_ID`,
/// `AWS_SECRET_ACCESS_KEY`, `AWS_ALLOW_HTTP`...), or explicit settings.
#[derive(Debug, Clone, Default)]
pub struct S3Settings {
    pub endpoint: Option<String>,
    pub region: Option<String>,
    pub access_key_id: Option<String>,
    pub secret_access_key: Option<String>,
    pub allow_http: bool,
}

/// One remote location, opened.
pub struct Remote {
    url: String,
    store: Arc<dyn ObjectStore>,
    prefix: ObjectPath,
    rt: tokio::runtime::Runtime,
}

/// The sync state kept beside a mirror: each object's ETag and the local
/// copy's size and modification time when they last matched.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
struct SyncState {
    objects: BTreeMap<String, Synced>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
struct Synced {
    etag: Option<String>,
    /// The object's last-modified time (RFC 3339): its identity where a
    /// listing gives no ETag (some S3-compatible servers).
    #[serde(default)]
    remote_modified: Option<String>,
    size: u64,
    mtime_ns: u128,
}

/// One object as listed.
#[derive(Debug, Clone)]
struct Listed {
    etag: Option<String>,
    modified: String,
    size: u64,
}

impl Synced {
    /// Whether `obj` is the object this entry was synced with.
    fn same_remote(&self, obj: &Listed) -> bool {
        match &obj.etag {
            Some(e) => self.etag.as_deref() == Some(e.as_str()),
            None => self.remote_modified.as_deref() == Some(obj.modified.as_str()),
        }
    }
}

/// Name of the sync state file in a mirror (never uploaded).
const STATE_FILE: &str = ".tirewear-remote.json";

/// What a pull or a push moved.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct SyncReport {
    pub transferred: usize,
    pub bytes: u64,
    pub deleted: usize,
    pub unchanged: usize,
}

/// Writes `bytes` to `path` through a temporary file and a rename.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), NightlyError> {
    crate::atomic::write_bytes(path, bytes).map_err(NightlyError::io(path))
}

/// An ETag without its quotes (listings and put responses differ in them).
fn unquote(etag: &str) -> String {
    etag.trim().trim_matches('"').to_string()
}

fn local_stamp(path: &Path) -> Option<(u64, u128)> {
    let m = std::fs::metadata(path).ok()?;
    let t = m
        .modified()
        .ok()?
        .duration_since(std::time::UNIX_EPOCH)
        .ok()?
        .as_nanos();
    Some((m.len(), t))
}

/// Files under `root` (relative paths with `/`), except the sync state,
/// the lock, staging and commit journals: what a dataset publishes.
fn local_files(root: &Path) -> Vec<String> {
    fn walk(dir: &Path, rel: &str, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let r = if rel.is_empty() {
                name.clone()
            } else {
                format!("{rel}/{name}")
            };
            match e.file_type() {
                // Staged parts are not committed: never published.
                Ok(t) if t.is_dir() && r != "staging" => walk(&e.path(), &r, out),
                Ok(t) if t.is_file() => {
                    let private = name == STATE_FILE
                        || name == ".lock"
                        || name.starts_with(".commit")
                        || name.contains(".tmp");
                    if !private {
                        out.push(r);
                    }
                }
                _ => {}
            }
        }
    }
    let mut out = Vec::new();
    walk(root, "", &mut out);
    out.sort();
    out
}

impl Remote {
    pub fn open(loc: &Location, settings: &S3Settings) -> Result<Remote, NightlyError> {
        let Location::S3 { bucket, prefix } = loc else {
            return Err(NightlyError::Invalid(format!(
                "{} is not an s3:// location",
                loc.url()
            )));
        };
        let url = loc.url();
        let mut b = AmazonS3Builder::from_env().with_bucket_name(bucket);
        if let Some(e) = &settings.endpoint {
            b = b.with_endpoint(e);
        }
        if let Some(r) = &settings.region {
            b = b.with_region(r);
        }
        if let Some(k) = &settings.access_key_id {
            b = b.with_access_key_id(k);
        }
        if let Some(k) = &settings.secret_access_key {
            b = b.with_secret_access_key(k);
        }
        if settings.allow_http {
            b = b.with_allow_http(true);
        }
        let store = b.build().map_err(|source| NightlyError::Remote {
            url: url.clone(),
            what: "opening the store".into(),
            source,
        })?;
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .map_err(NightlyError::io(PathBuf::from(&url)))?;
        Ok(Remote {
            url,
            store: Arc::new(store),
            prefix: ObjectPath::from(prefix.as_str()),
            rt,
        })
    }

    fn err(&self, what: String) -> impl FnOnce(object_store::Error) -> NightlyError + '_ {
        move |source| NightlyError::Remote {
            url: self.url.clone(),
            what,
            source,
        }
    }

    fn key(&self, rel: &str) -> ObjectPath {
        let mut p = self.prefix.clone();
        for part in rel.split('/') {
            p = p.child(part);
        }
        p
    }

    /// Every object under the prefix, by relative key.
    fn list(&self) -> Result<BTreeMap<String, Listed>, NightlyError> {
        use futures::TryStreamExt;
        let store = self.store.clone();
        let prefix = self.prefix.clone();
        let metas: Result<Vec<object_store::ObjectMeta>, _> = self.rt.block_on(async move {
            let p = (!prefix.as_ref().is_empty()).then_some(&prefix);
            store.list(p).try_collect().await
        });
        let metas = metas.map_err(self.err("listing".into()))?;
        let n = self.prefix.parts().count();
        Ok(metas
            .into_iter()
            .map(|m| {
                let rel: Vec<String> = m
                    .location
                    .parts()
                    .skip(n)
                    .map(|p| p.as_ref().to_string())
                    .collect();
                let listed = Listed {
                    etag: m.e_tag.map(|e| unquote(&e)),
                    modified: m.last_modified.to_rfc3339(),
                    size: m.size,
                };
                (rel.join("/"), listed)
            })
            .collect())
    }

    fn read_state(dir: &Path) -> SyncState {
        std::fs::read(dir.join(STATE_FILE))
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
            .unwrap_or_default()
    }

    fn write_state(dir: &Path, s: &SyncState) -> Result<(), NightlyError> {
        let path = dir.join(STATE_FILE);
        let bytes = serde_json::to_vec_pretty(s).expect("serialisable");
        write_atomic(&path, &bytes)
    }

    /// Brings the local mirror `dir` to the remote's state: downloads the
    /// objects whose ETag changed, deletes local copies of removed objects.
    pub fn pull(&self, dir: &Path) -> Result<SyncReport, NightlyError> {
        std::fs::create_dir_all(dir).map_err(NightlyError::io(dir))?;
        let remote = self.list()?;
        let mut state = Self::read_state(dir);
        let mut report = SyncReport::default();
        for (rel, obj) in &remote {
            let local = dir.join(rel);
            let current = state.objects.get(rel).is_some_and(|s| {
                s.same_remote(obj) && local_stamp(&local) == Some((s.size, s.mtime_ns))
            });
            if current {
                report.unchanged += 1;
                continue;
            }

            let key = self.key(rel);
            let store = self.store.clone();
            let (meta, bytes) = self
                .rt
                .block_on(async move {
                    let r = store.get(&key).await?;
                    let meta = r.meta.clone();
                    Ok::<_, object_store::Error>((meta, r.bytes().await?))
                })
                .map_err(self.err(format!("downloading {rel}")))?;
            if let Some(parent) = local.parent() {
                std::fs::create_dir_all(parent).map_err(NightlyError::io(parent))?;
            }
            write_atomic(&local, &bytes)?;
            let (size, mtime_ns) = local_stamp(&local).unwrap_or((obj.size, 0));
            state.objects.insert(
                rel.clone(),
                Synced {
                    etag: obj.etag.clone().or(meta.e_tag.map(|e| unquote(&e))),
                    remote_modified: Some(obj.modified.clone()),
                    size,
                    mtime_ns,
                },
            );
            report.transferred += 1;
            report.bytes += bytes.len() as u64;
        }
        let gone: Vec<String> = state
            .objects
            .keys()
            .filter(|k| !remote.contains_key(*k))
            .cloned()
            .collect();
        for rel in gone {
            let _ = std::fs::remove_file(dir.join(&rel));
            state.objects.remove(&rel);
            report.deleted += 1;
        }
        Self::write_state(dir, &state)?;
        Ok(report)
    }

    /// Publishes the local dataset `dir`: uploads changed files, deletes
    /// remote objects no longer there, then puts `commit_file` last,
    /// conditionally on the remote copy being the one last pulled.
    pub fn push(&self, dir: &Path, commit_file: &str) -> Result<SyncReport, NightlyError> {
        let mut state = Self::read_state(dir);
        let files = local_files(dir);
        let mut report = SyncReport::default();
        for rel in files.iter().filter(|r| r.as_str() != commit_file) {
            let local = dir.join(rel);
            let stamp = local_stamp(&local);
            if state
                .objects
                .get(rel)
                .is_some_and(|s| Some((s.size, s.mtime_ns)) == stamp)
            {
                report.unchanged += 1;
                continue;
            }
            self.upload(
                &mut state,
                &mut report,
                rel,
                &local,
                stamp,
                PutMode::Overwrite,
            )?;
        }
        let gone: Vec<String> = state
            .objects
            .keys()
            .filter(|k| k.as_str() != commit_file && !files.contains(k))
            .cloned()
            .collect();
        for rel in gone {
            let key = self.key(&rel);
            let store = self.store.clone();
            self.rt
                .block_on(async move { store.delete(&key).await })
                .map_err(self.err(format!("deleting {rel}")))?;
            state.objects.remove(&rel);
            report.deleted += 1;
        }
        // Uploaded objects are saved in the state now: a failed commit put
        // below does not make them look new again.
        Self::write_state(dir, &state)?;
        let local = dir.join(commit_file);
        let stamp = local_stamp(&local);
        let known = state.objects.get(commit_file).cloned();
        if stamp.is_some() && known.as_ref().map(|s| (s.size, s.mtime_ns)) != stamp {
            let mode = match known.and_then(|s| s.etag) {
                Some(e_tag) => PutMode::Update(UpdateVersion {
                    e_tag: Some(e_tag),
                    version: None,
                }),
                None => PutMode::Create,
            };
            self.upload(&mut state, &mut report, commit_file, &local, stamp, mode)?;
        }
        // The uploaded objects' remote identity, for the next pull.
        for (rel, obj) in self.list()? {
            if let Some(s) = state.objects.get_mut(&rel) {
                s.remote_modified = Some(obj.modified);
                if s.etag.is_none() {
                    s.etag = obj.etag;
                }
            }
        }
        Self::write_state(dir, &state)?;
        Ok(report)
    }

    /// Uploads `local` as `rel` and records it in the sync state.
    fn upload(
        &self,
        state: &mut SyncState,
        report: &mut SyncReport,
        rel: &str,
        local: &Path,
        stamp: Option<(u64, u128)>,
        mode: PutMode,
    ) -> Result<(), NightlyError> {
        let etag = self.put(rel, local, mode)?;
        let (size, mtime_ns) = stamp.unwrap_or_default();
        let synced = Synced {
            etag,
            size,
            mtime_ns,
            ..Synced::default()
        };
        state.objects.insert(rel.to_string(), synced);
        report.transferred += 1;
        report.bytes += size;
        Ok(())
    }

    fn put(&self, rel: &str, local: &Path, mode: PutMode) -> Result<Option<String>, NightlyError> {
        let bytes = std::fs::read(local).map_err(NightlyError::io(local))?;
        let key = self.key(rel);
        let store = self.store.clone();
        let conditional = !matches!(mode, PutMode::Overwrite);
        let opts = PutOptions {
            mode,
            ..PutOptions::default()
        };
        let r = self
            .rt
            .block_on(async move { store.put_opts(&key, PutPayload::from(bytes), opts).await });
        match r {
            Ok(res) => Ok(res.e_tag.map(|e| unquote(&e))),
            Err(
                object_store::Error::Precondition { .. }
                | object_store::Error::AlreadyExists { .. },
            ) if conditional => Err(NightlyError::Conflict {
                url: self.url.clone(),
                what: format!(
                    "{rel} changed since this process pulled it: another process committed the dataset; nothing was published over it (run again)"
                ),
            }),
            Err(e) => Err(self.err(format!("uploading {rel}"))(e)),
        }
    }
}

/// The remote side of one `process` invocation: the local folders to
/// process (mirrors of the `s3://` locations under the cache), and the
/// remote dataset to publish to afterwards.
pub struct Session {
    dataset: Option<Remote>,
    /// Local folder of the dataset (its mirror when remote).
    pub dataset_dir: PathBuf,
    /// Local folders of the archives, in order.
    pub archive_dirs: Vec<PathBuf>,
    /// What each pull moved: (location, report).
    pub pulled: Vec<(String, SyncReport)>,
}

impl Session {
    /// Opens the remote locations and pulls them into `cache` (needed as
    /// soon as one location is remote). A local location is used as it is.
    pub fn prepare(
        archives: &[Location],
        dataset: &Location,
        cache: Option<&Path>,
        settings: &S3Settings,
    ) -> Result<Session, NightlyError> {
        let any_remote = std::iter::once(dataset)
            .chain(archives)
            .any(|l| matches!(l, Location::S3 { .. }));
        let cache = match (any_remote, cache) {
            (true, None) => {
                return Err(NightlyError::Invalid(
                    "an s3:// location needs a local cache folder (--cache DIR or TIREWEAR_CACHE)"
                        .into(),
                ));
            }
            (_, c) => c.map(Path::to_path_buf).unwrap_or_default(),
        };
        let mut pulled = Vec::new();
        let mut pull = |loc: &Location| -> Result<(PathBuf, Option<Remote>), NightlyError> {
            let dir = loc.mirror(&cache);
            if !matches!(loc, Location::S3 { .. }) {
                return Ok((dir, None));
            }
            let r = Remote::open(loc, settings)?;
            let rep = r.pull(&dir)?;
            tracing::info!(
                location = %loc.url(),
                downloaded = rep.transferred,
                bytes = rep.bytes,
                unchanged = rep.unchanged,
                "pulled"
            );
            pulled.push((loc.url(), rep));
            Ok((dir, Some(r)))
        };
        let (dataset_dir, dataset_remote) = pull(dataset)?;
        let mut archive_dirs = Vec::new();
        for a in archives {
            archive_dirs.push(pull(a)?.0);
        }
        Ok(Session {
            dataset: dataset_remote,
            dataset_dir,
            archive_dirs,
            pulled,
        })
    }

    /// Publishes the local dataset to its remote location (nothing for a
    /// local dataset): changed files, then `dataset.json` conditionally.
    pub fn publish(&self) -> Result<Option<SyncReport>, NightlyError> {
        self.dataset
            .as_ref()
            .map(|r| r.push(&self.dataset_dir, "dataset.json"))
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_parse() {
        assert_eq!(
            Location::parse("s3://b/x/y/").unwrap(),
            Location::S3 {
                bucket: "b".into(),
                prefix: "x/y".into()
            }
        );
        assert_eq!(
            Location::parse("s3://b").unwrap(),
            Location::S3 {
                bucket: "b".into(),
                prefix: "".into()
            }
        );
        assert_eq!(
            Location::parse("data/x").unwrap(),
            Location::Local("data/x".into())
        );
        assert!(Location::parse("s3:///x").is_err());
        let m = Location::parse("s3://b/x/y")
            .unwrap()
            .mirror(Path::new("/c"));
        assert_eq!(m, PathBuf::from("/c/s3/b/x/y"));
    }

    /// A remote dataset holds an archive at its prefix or below it, part by
    /// part (`x/yz` is not under `x/y`), in its own bucket only.
    #[test]
    fn a_remote_dataset_holds_archives_at_or_below_its_prefix() {
        let at = |s: &str| Location::parse(s).unwrap();
        assert!(at("s3://b/x").holds(&at("s3://b/x/")));
        assert!(at("s3://b/x").holds(&at("s3://b/x/y")));
        assert!(at("s3://b").holds(&at("s3://b/x")));
        assert!(!at("s3://b/x/y").holds(&at("s3://b/x")));
        assert!(!at("s3://b/x/y").holds(&at("s3://b/x/yz")));
        assert!(!at("s3://b/x").holds(&at("s3://c/x")));
        assert!(!at("data").holds(&at("data")));
    }
}
