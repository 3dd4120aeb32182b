//! `process` with archives and datasets on S3-compatible object storage,
//! against a local S3 server started here (s3s-fs, on 127.0.0.1): the
//! published dataset is byte-identical to a local run's, a rerun transfers
//! and processes nothing, a changed object reprocesses only its run, and a
//! commit put over another process's commit is refused.

mod common;

use std::path::{Path, PathBuf};
use tirewear::nightly::remote::{Location, S3Settings, Session};
use tirewear::nightly::{ProcessOptions, process};

/// Starts an S3 server over `root` (a bucket is a folder) on a free
/// loopback port; it lives as long as the returned runtime.
fn start_server(root: &Path) -> (tokio::runtime::Runtime, String) {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let root = root.to_path_buf();
    let addr = rt.block_on(async move {
        let fs = s3s_fs::FileSystem::new(root).unwrap();
        let mut b = s3s::service::S3ServiceBuilder::new(fs);
        // The same keys as `settings`: requests are signed and checked.
        b.set_auth(s3s::auth::SimpleAuth::from_single("test", "test"));
        let service = b.build();
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        tokio::spawn(async move {
            let http =
                hyper_util::server::conn::auto::Builder::new(hyper_util::rt::TokioExecutor::new());
            loop {
                let Ok((socket, _)) = listener.accept().await else {
                    continue;
                };
                let conn =
                    http.serve_connection(hyper_util::rt::TokioIo::new(socket), service.clone());
                let conn = conn.into_owned();
                tokio::spawn(async move {
                    let _ = conn.await;
                });
            }
        });
        addr
    });
    (rt, format!("http://{addr}"))
}

fn settings(endpoint: &str) -> S3Settings {
    S3Settings {
        endpoint: Some(endpoint.into()),
        region: Some("us-east-1".into()),
        access_key_id: Some("test".into()),
        secret_access_key: Some("test".into()),
        allow_http: true,
    }
}

/// Runs `process` through a session: pull, process, publish.
fn run_remote(
    archive: &str,
    dataset: &str,
    cache: &Path,
    s: &S3Settings,
) -> (tirewear::nightly::ProcessSummary, Session) {
    let archives = vec![Location::parse(archive).unwrap()];
    let ds = Location::parse(dataset).unwrap();
    let session = Session::prepare(&archives, &ds, Some(cache), s).unwrap();
    let opts = ProcessOptions::new(session.archive_dirs.clone(), session.dataset_dir.clone());
    let summary = process(&opts).unwrap();
    session.publish().unwrap();
    (summary, session)
}

fn count_files(dir: &Path) -> usize {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            if e.file_type().unwrap().is_dir() {
                count_files(&e.path())
            } else {
                1
            }
        })
        .sum()
}

fn bytes(p: PathBuf) -> Vec<u8> {
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A server over a bucket folder holding the tiny season (seed 3) under
/// `archive_prefix`: (its folder, the bucket folder, the local archive,
/// the running server, the settings to reach it).
struct Bucket {
    tmp: tempfile::TempDir,
    bucket: PathBuf,
    archive: PathBuf,
    _rt: tokio::runtime::Runtime,
    settings: S3Settings,
}

fn bucket_with_tiny_season(archive_prefix: &str) -> Bucket {
    let tmp = tempfile::tempdir().unwrap();
    let server_root = tmp.path().join("s3");
    let bucket = server_root.join("bucket");
    std::fs::create_dir_all(&bucket).unwrap();
    let (rt, endpoint) = start_server(&server_root);
    let archive = tmp.path().join("archive");
    common::simulate_tiny(&archive, 3);
    common::copy_dir(&archive, &bucket.join(archive_prefix));
    Bucket {
        tmp,
        bucket,
        archive,
        _rt: rt,
        settings: settings(&endpoint),
    }
}

#[test]
fn a_dataset_on_s3_matches_a_local_run_and_reruns_incrementally() {
    let b = bucket_with_tiny_season("seasons/tiny");
    let (tmp, bucket, local_archive, s) = (
        b.tmp.path(),
        b.bucket.clone(),
        b.archive.clone(),
        b.settings.clone(),
    );

    // The reference: the same archive processed locally.
    let local_ds = tmp.join("local-ds");
    process(&ProcessOptions::new(vec![local_archive.clone()], &local_ds)).unwrap();

    let cache = tmp.join("cache");
    let (first, session) = run_remote(
        "s3://bucket/seasons/tiny",
        "s3://bucket/datasets/tiny",
        &cache,
        &s,
    );
    assert!(first.committed);
    assert_eq!(first.processed, 4);
    assert_eq!(
        session.pulled[1].1.transferred,
        count_files(&local_archive),
        "{:?}",
        session.pulled
    );
    // Published objects are the local run's bytes, dataset.json included
    // (its run keys do not depend on where the archive was read from).
    let remote_ds = bucket.join("datasets/tiny");
    for f in [
        "kpis.parquet",
        "kpis.energy_maps.parquet",
        "kpis.road.parquet",
    ] {
        assert_eq!(bytes(remote_ds.join(f)), bytes(local_ds.join(f)), "{f}");
    }
    assert!(remote_ds.join("dataset.json").exists());
    assert!(!remote_ds.join(".lock").exists() && !remote_ds.join("staging").exists());

    // A rerun: nothing downloaded, nothing processed, nothing re-uploaded but the summary.
    let (second, session) = run_remote(
        "s3://bucket/seasons/tiny",
        "s3://bucket/datasets/tiny",
        &cache,
        &s,
    );
    assert_eq!(second.processed, 0);
    assert!(!second.committed);
    assert!(
        session.pulled.iter().all(|(_, r)| r.transferred == 0),
        "{:?}",
        session.pulled
    );

    // A changed wear reading in the bucket: only its run is processed.
    let wear = bucket.join("seasons/tiny/wear/readings.csv");
    let text = std::fs::read_to_string(&wear).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let header: Vec<&str> = lines[0].split(',').collect();
    let col = header
        .iter()
        .position(|h| h.starts_with("depth"))
        .expect("a depth column");
    let mut cells: Vec<String> = lines[1].split(',').map(str::to_string).collect();
    let v: f64 = cells[col].parse().unwrap();
    cells[col] = format!("{:.3}", v - 0.2);
    lines[1] = cells.join(",");
    std::fs::write(&wear, lines.join("\n") + "\n").unwrap();
    let (third, session) = run_remote(
        "s3://bucket/seasons/tiny",
        "s3://bucket/datasets/tiny",
        &cache,
        &s,
    );
    assert_eq!(
        session.pulled[1].1.transferred, 1,
        "only the readings: {:?}",
        session.pulled
    );
    assert_eq!(third.processed, 1);
    assert!(third.committed);
    let published: serde_json::Value =
        serde_json::from_slice(&bytes(remote_ds.join("dataset.json"))).unwrap();
    let local_state: serde_json::Value =
        serde_json::from_slice(&bytes(session.dataset_dir.join("dataset.json"))).unwrap();
    assert_eq!(published, local_state);
}

#[test]
fn a_commit_over_another_processs_commit_is_refused() {
    let b = bucket_with_tiny_season("a");
    let (tmp, bucket, s) = (b.tmp.path(), b.bucket.clone(), b.settings.clone());
    let a = Location::parse("s3://bucket/a").unwrap();
    let ds = Location::parse("s3://bucket/ds").unwrap();

    // Two machines pull the empty dataset; the first publishes.
    let one = Session::prepare(std::slice::from_ref(&a), &ds, Some(&tmp.join("c1")), &s).unwrap();
    let two = Session::prepare(std::slice::from_ref(&a), &ds, Some(&tmp.join("c2")), &s).unwrap();
    process(&ProcessOptions::new(
        one.archive_dirs.clone(),
        one.dataset_dir.clone(),
    ))
    .unwrap();
    one.publish().unwrap();
    let published = bytes(bucket.join("ds/dataset.json"));
    // The second commits its own dataset and tries to publish it: refused.
    process(&ProcessOptions::new(
        two.archive_dirs.clone(),
        two.dataset_dir.clone(),
    ))
    .unwrap();
    let e = two.publish().unwrap_err().to_string();
    assert!(e.contains("another process committed"), "{e}");
    assert_eq!(
        bytes(bucket.join("ds/dataset.json")),
        published,
        "the first commit stands"
    );
}
