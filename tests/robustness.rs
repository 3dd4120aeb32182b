//! Robustness suite (docs/reliability.md): seeded mutations of every input
//! format. For each mutated input: no panic, no abort, bounded memory, and
//! either an error that names the file or a result identical to the
//! undamaged input (MCAP), or finite KPIs wherever the row's `quality` says
//! "ok" (the other formats, where a mutation can be valid data).
//!
//! A valid KPI table with absurd numbers must not panic the diagnosis, the
//! fits or the predictions.
//!
//! The MCAP files are the committed fixtures: two written by tirewear and
//! two by Python's `mcap` writer (tests/oracles/write_python_mcap.py), so the
//! checks do not rest on our own writer alone.

mod common;

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use tirewear::ingest::telemetry::{RunTelemetry, read_telemetry};

/// Counts live heap bytes and their peak, so each read's memory is measured.
struct Counting;
static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let now = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            if new_size >= layout.size() {
                let now = LIVE.fetch_add(new_size - layout.size(), Ordering::Relaxed)
                    + (new_size - layout.size());
                PEAK.fetch_max(now, Ordering::Relaxed);
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
            }
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The tests of this binary measure memory: one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

/// Largest extra heap one read of a ~100 KB fixture may take (the undamaged
/// reads take under 4 MiB).
const MEMORY_BOUND: usize = 64 << 20;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// Offsets of the top-level MCAP records (opcode byte), walking the length fields.
fn record_offsets(b: &[u8]) -> Vec<usize> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= b.len() {
        out.push(at);
        let len = u64::from_le_bytes(b[at + 1..at + 9].try_into().unwrap());
        match (at as u64 + 9).checked_add(len) {
            Some(next) if next <= b.len() as u64 => at = next as usize,
            _ => break,
        }
    }
    out
}

/// One seeded mutation of an MCAP file's bytes, and its name for messages.
fn mutate_mcap(b: &[u8], rng: &mut ChaCha8Rng) -> (Vec<u8>, String) {
    let mut m = b.to_vec();
    let n = m.len();
    let records = record_offsets(b);
    let mut kind = rng.random_range(0..7);
    if records.is_empty() && kind == 3 {
        kind = 0;
    }
    let what = match kind {
        0 => {
            let flips = rng.random_range(1..=4);
            let mut at = Vec::new();
            for _ in 0..flips {
                let (i, bit) = (rng.random_range(0..n), rng.random_range(0..8));
                m[i] ^= 1 << bit;
                at.push(format!("{i}.{bit}"));
            }
            format!("bit flips at {}", at.join(","))
        }
        1 => {
            let len = rng.random_range(0..n);
            m.truncate(len);
            format!("truncated to {len}")
        }
        2 => {
            let start = rng.random_range(0..n);
            let len = rng.random_range(1..=64).min(n - start);
            rng.fill_bytes(&mut m[start..start + len]);
            format!("{len} random bytes at {start}")
        }
        3 => {
            // A record's length field set huge, or just off by a little.
            let r = records[rng.random_range(0..records.len())];
            let old = u64::from_le_bytes(m[r + 1..r + 9].try_into().unwrap());
            let new = match rng.random_range(0..3) {
                0 => u64::MAX - rng.random_range(0..1000),
                1 => 1 << rng.random_range(20..48),
                _ => old.wrapping_add_signed(rng.random_range(-16..=16)),
            };
            m[r + 1..r + 9].copy_from_slice(&new.to_le_bytes());
            format!("record at {r}: length {old} -> {new}")
        }
        4 => {
            // A chunk's declared uncompressed size or compression changed.
            let chunks: Vec<usize> = records.iter().copied().filter(|&r| b[r] == 0x06).collect();
            if chunks.is_empty() {
                m[n / 2] ^= 0x10;
                return (m, format!("bit flip at {}", n / 2));
            }
            let c = chunks[rng.random_range(0..chunks.len())];
            if rng.random_bool(0.5) {
                let size = rng.random_range(0..1u64 << 40);
                m[c + 25..c + 33].copy_from_slice(&size.to_le_bytes());
                format!("chunk at {c}: uncompressed size -> {size}")
            } else {
                let name_len = u32::from_le_bytes(m[c + 37..c + 41].try_into().unwrap()) as usize;
                for k in 0..name_len {
                    m[c + 41 + k] = b"lz4x"[k % 4];
                }
                format!("chunk at {c}: compression renamed")
            }
        }
        5 => {
            // A run of zeros (a sector that read back blank).
            let start = rng.random_range(0..n);
            let len = rng.random_range(1..=512).min(n - start);
            m[start..start + len].fill(0);
            format!("{len} zero bytes at {start}")
        }
        _ => {
            // Bytes cut out of the middle: every later offset moves.
            let start = rng.random_range(0..n);
            let len = rng.random_range(1..=32).min(n - start);
            m.drain(start..start + len);
            format!("{len} bytes removed at {start}")
        }
    };
    (m, what)
}

/// Reads `path` with panics caught and the heap's peak measured.
fn read_measured(
    path: &Path,
) -> (
    std::thread::Result<tirewear::ingest::Result<RunTelemetry>>,
    usize,
) {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let r = std::panic::catch_unwind(|| read_telemetry(path));
    let peak = PEAK.load(Ordering::Relaxed).saturating_sub(base);
    (r, peak)
}

#[test]
fn mutated_mcap_files_are_refused_by_name_or_read_identically() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let per_file = 520;
    let (mut errors, mut identical, mut failures) = (0, 0, Vec::new());
    let mut peak_max = 0;
    for (fi, name) in [
        "tiny-block.mcap",
        "tiny-sample.mcap",
        "python-block.mcap",
        "python-sample.mcap",
    ]
    .into_iter()
    .enumerate()
    {
        let original = std::fs::read(fixture(name)).unwrap();
        let expected = read_telemetry(&fixture(name)).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + fi as u64);
        for case in 0..per_file {
            let (bytes, what) = mutate_mcap(&original, &mut rng);
            if bytes == original {
                continue;
            }
            let path = dir.path().join(format!("m{fi}-{case}.mcap"));
            std::fs::write(&path, &bytes).unwrap();
            let (r, peak) = read_measured(&path);
            peak_max = peak_max.max(peak);
            let tag = format!("{name} case {case} ({what})");
            if peak > MEMORY_BOUND {
                failures.push(format!("{tag}: {peak} bytes of heap"));
            }
            match r {
                Err(_) => failures.push(format!("{tag}: panicked")),
                Ok(Err(e)) => {
                    let msg = e.to_string();
                    if msg.contains(path.to_str().unwrap()) {
                        errors += 1;
                    } else {
                        failures.push(format!("{tag}: error does not name the file: {msg}"));
                    }
                }
                Ok(Ok(t)) if t == expected => identical += 1,
                Ok(Ok(_)) => failures.push(format!("{tag}: read without error but differs")),
            }
            std::fs::remove_file(&path).unwrap();
        }
    }
    println!(
        "MCAP mutations: {} tried, {errors} refused by name, {identical} read identically, \
         {} failures; peak heap of one read {peak_max} bytes",
        errors + identical + failures.len(),
        failures.len()
    );
    assert!(errors + identical + failures.len() >= 2000);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Rewrites an MCAP file message by message through `mcap::Writer`, letting
/// `edit` change one message's data: the result has valid CRCs, so only the
/// protobuf and block checks stand between the damage and the KPIs.
fn rewrite(src: &Path, dst: &Path, target: usize, edit: impl Fn(&mut Vec<u8>)) {
    let bytes = std::fs::read(src).unwrap();
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .create(std::io::BufWriter::new(std::fs::File::create(dst).unwrap()))
        .unwrap();
    let mut channels = std::collections::HashMap::new();
    for (i, msg) in mcap::MessageStream::new(&bytes).unwrap().enumerate() {
        let msg = msg.unwrap();
        let id = *channels.entry(msg.channel.id).or_insert_with(|| {
            let s = msg.channel.schema.as_ref().unwrap();
            let sid = w.add_schema(&s.name, &s.encoding, &s.data).unwrap();
            w.add_channel(sid, &msg.channel.topic, "protobuf", &Default::default())
                .unwrap()
        });
        let mut data = msg.data.to_vec();
        if i == target {
            edit(&mut data);
        }
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: id,
                sequence: msg.sequence,
                log_time: msg.log_time,
                publish_time: msg.publish_time,
            },
            &data,
        )
        .unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn damaged_protobuf_and_stretched_blocks_are_refused_or_harmless() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let mut failures = Vec::new();
    let (mut tried, mut refused) = (0, 0);
    for name in ["tiny-block.mcap", "tiny-sample.mcap", "python-block.mcap"] {
        let src = fixture(name);
        let n_msgs = mcap::MessageStream::new(&std::fs::read(&src).unwrap())
            .unwrap()
            .count();
        for case in 0..40 {
            let target = rng.random_range(0..n_msgs);
            let seed: u64 = rng.random();
            let dst = dir.path().join(format!("p-{case}.mcap"));
            rewrite(&src, &dst, target, |d| {
                let mut r = ChaCha8Rng::seed_from_u64(seed);
                match r.random_range(0..3) {
                    0 if !d.is_empty() => {
                        let i = r.random_range(0..d.len());
                        d[i] ^= 1 << r.random_range(0..8);
                    }
                    1 => d.truncate(r.random_range(0..=d.len())),
                    _ => d.extend((0..r.random_range(1..64)).map(|_| r.random::<u8>())),
                }
            });
            let (res, peak) = read_measured(&dst);
            tried += 1;
            let tag = format!("{name} message {target}");
            match res {
                Err(_) => failures.push(format!("{tag}: panicked")),
                Ok(Err(e)) if !e.to_string().contains(dst.to_str().unwrap()) => {
                    failures.push(format!("{tag}: error does not name the file: {e}"))
                }
                Ok(Err(_)) => refused += 1,
                Ok(Ok(_)) => {}
            }
            if peak > MEMORY_BOUND {
                failures.push(format!("{tag}: {peak} bytes of heap"));
            }
        }
    }
    println!(
        "damaged protobuf: {tried} files, {refused} refused with the file named, {} read \
         (valid files with other values), {} failures",
        tried - refused - failures.len(),
        failures.len()
    );
    assert!(tried >= 120);
    assert!(failures.is_empty(), "{}", failures.join("\n"));

    // A block whose arrays were extended (the lengths agree, the CRCs are
    // valid): its topic then runs far past the others and is refused.
    use prost::Message;
    use tirewear::ingest::telemetry::proto::TireBlock;
    let src = fixture("tiny-block.mcap");
    let dst = dir.path().join("stretched.mcap");
    rewrite(&src, &dst, 0, |d| {
        let mut b = TireBlock::decode(d.as_slice()).unwrap();
        let extra = 50_000;
        for v in [
            &mut b.vx_mps,
            &mut b.vy_mps,
            &mut b.omega_radps,
            &mut b.rolling_radius_m,
            &mut b.fx_n,
            &mut b.fy_n,
            &mut b.fz_n,
            &mut b.t_surface_c,
            &mut b.t_inner_c,
            &mut b.pressure_pa,
            &mut b.camber_deg,
        ] {
            let last = *v.last().unwrap();
            v.extend(std::iter::repeat_n(last, extra));
        }
        *d = b.encode_to_vec();
    });
    let err = read_telemetry(&dst).unwrap_err().to_string();
    assert!(
        err.contains("stretched.mcap") && err.contains("spans") && err.contains("/tire/"),
        "{err}"
    );
}

/// Replaces the `k`-th number of a text file with one of the values that
/// broke readers before (NaN, infinities, huge, tiny, zero, negative, text).
fn replace_number(text: &str, rng: &mut ChaCha8Rng) -> (String, String) {
    let spans: Vec<(usize, usize)> = {
        let b = text.as_bytes();
        let mut v = Vec::new();
        let mut i = 0;
        while i < b.len() {
            if b[i].is_ascii_digit() {
                let s = i;
                while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.' || b[i] == b'e') {
                    i += 1;
                }
                v.push((s, i));
            } else {
                i += 1;
            }
        }
        v
    };
    if spans.is_empty() {
        return (text.to_string(), "no number".into());
    }
    let (s, e) = spans[rng.random_range(0..spans.len())];
    const VALUES: [&str; 12] = [
        "nan",
        "inf",
        "-inf",
        "1e308",
        "-1e308",
        "0",
        "-1",
        "1e-300",
        "abc",
        "",
        "-500",
        "99999999999999999999",
    ];
    let v = VALUES[rng.random_range(0..VALUES.len())];
    let out = format!("{}{v}{}", &text[..s], &text[e..]);
    (out, format!("'{}' -> '{v}' at byte {s}", &text[s..e]))
}

fn mutate_text(text: &str, rng: &mut ChaCha8Rng) -> (Vec<u8>, String) {
    match rng.random_range(0..4) {
        0 | 1 => {
            let (t, what) = replace_number(text, rng);
            (t.into_bytes(), what)
        }
        2 => {
            let n = rng.random_range(0..text.len());
            (text.as_bytes()[..n].to_vec(), format!("truncated to {n}"))
        }
        _ => {
            let mut lines: Vec<&str> = text.lines().collect();
            let i = rng.random_range(0..lines.len());
            let what = if rng.random_bool(0.5) {
                lines.remove(i);
                format!("line {} removed", i + 1)
            } else {
                lines.insert(i, lines[i]);
                format!("line {} doubled", i + 1)
            };
            (lines.join("\n").into_bytes(), what)
        }
    }
}

#[test]
fn mutated_manifests_compounds_roads_and_wear_never_panic() {
    use tirewear::ingest::manifest::Season;
    use tirewear::kpi::{ExtractOptions, extract, table};
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let season_dir = dir.path().join("season");
    tirewear::sim::simulate(&tirewear::sim::SimOptions {
        preset: tirewear::sim::Preset::Tiny,
        scale: 1.0,
        tracks: None,
        seed: 5,
        effects: vec![],
        generated: None,
        scatter: tirewear::sim::WearScatter::NONE,
        encoding: tirewear::ingest::telemetry::Encoding::Block,
        rate_hz: Some(5.0),
        out: season_dir.clone(),
        sensor_noise: true,
        logger_export: None,
        progress: false,
    })
    .unwrap();
    let season = Season::open(&season_dir).unwrap();
    let m = &season.manifest;
    let mut targets: Vec<String> = vec!["season.toml".into(), m.compounds[0].file.clone()];
    targets.push(m.wear_readings[0].clone());
    if let Some(p) = m.tracks.iter().flat_map(|t| t.profiles.first()).next() {
        targets.push(p.file.clone());
    }
    let bulk = m.road_profiles.clone();
    let opts = ExtractOptions::new(&season_dir, dir.path().join("out/kpis.parquet"));
    let mut rng = ChaCha8Rng::seed_from_u64(4242);
    let (mut tried, mut refused, mut failures) = (0, 0, Vec::new());
    let root = season_dir.to_str().unwrap().to_string();
    let mut check = |file: &str, what: String, failures: &mut Vec<String>| {
        tried += 1;
        let tag = format!("{file} ({what})");
        match std::panic::catch_unwind(|| extract(&opts)) {
            Err(_) => failures.push(format!("{tag}: panicked")),
            Ok(Err(e)) => {
                refused += 1;
                let msg = e.to_string();
                let leaf = Path::new(file).file_name().unwrap().to_str().unwrap();
                // The mutated file, or the file a mutated path now points at.
                if !(msg.contains(leaf) || msg.contains(&root)) {
                    failures.push(format!("{tag}: error does not name the file: {msg}"));
                }
            }
            Ok(Ok(_)) => {
                for r in table::read_parquet(&opts.out).unwrap() {
                    let finite = table::KpiRow::NUMBER_COLUMNS
                        .iter()
                        .all(|c| r.number(c).unwrap().is_finite());
                    if finite != (r.quality == table::QUALITY_OK) {
                        failures.push(format!(
                            "{tag}: run {} wheel {}: quality '{}' but finite = {finite}",
                            r.run, r.wheel, r.quality
                        ));
                    }
                }
            }
        }
    };
    for file in &targets {
        let path = season_dir.join(file);
        let original = std::fs::read_to_string(&path).unwrap();
        for _ in 0..40 {
            let (bytes, what) = mutate_text(&original, &mut rng);
            std::fs::write(&path, &bytes).unwrap();
            check(file, what, &mut failures);
        }
        std::fs::write(&path, &original).unwrap();
    }
    if let Some(bulk) = bulk {
        let path = season_dir.join(&bulk);
        let original = std::fs::read(&path).unwrap();
        for _ in 0..40 {
            let (bytes, what) = mutate_mcap(&original, &mut rng);
            std::fs::write(&path, &bytes).unwrap();
            check(&bulk, what, &mut failures);
        }
        std::fs::write(&path, &original).unwrap();
    }
    println!(
        "other formats: {tried} mutations, {refused} refused with the file named, {} failures",
        failures.len()
    );
    assert!(tried >= 160);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// KPI tables with absurd numbers (NaN, ±inf, ±1e300, 0, −1, denormals,
/// values scaled by 1e±6; one cell, a whole column, or many cells of the
/// demo's table) never panic the gap diagnosis, the physical and PCA fits
/// or the saved models' predictions: each gives a result or an error. A
/// column without a finite value once panicked the diagnosis's candidate
/// library (the contact patch's threshold grid), and a wear column of
/// denormals the fits (statrs, on 0/0 t-values).
#[test]
fn kpi_tables_with_absurd_values_never_panic_the_models_or_the_diagnosis() {
    use std::panic::{AssertUnwindSafe, catch_unwind};
    use tirewear::gap::report::{Baseline, GapSettings, diagnose};
    use tirewear::gap::scoring::ScoringSettings;
    use tirewear::kpi::KpiRow;
    use tirewear::model::fit::{FitSettings, Method, fit_method, split};
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let clean = common::demo_kpis(dir.path());
    let maps =
        tirewear::kpi::energy_maps::read_tire_maps(&dir.path().join("kpis.parquet")).unwrap();
    let settings = FitSettings::default();
    let models: Vec<_> = [Method::Physical, Method::Pca]
        .into_iter()
        .map(|m| {
            fit_method(m, &split(&clean, None).unwrap(), &settings)
                .unwrap()
                .0
        })
        .collect();
    let gap = GapSettings {
        scoring: ScoringSettings {
            permutations: 99,
            ..Default::default()
        },
        ..Default::default()
    };
    const ABSURD: [f64; 9] = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        1e300,
        -1e300,
        0.0,
        -1.0,
        1e-300,
        5e-324,
    ];
    let columns = KpiRow::NUMBER_COLUMNS;
    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    let mut failures = Vec::new();
    let (mut diagnosed, mut refused) = (0, 0);
    for case in 0..18 {
        let mut rows = clean.clone();
        let mut what = Vec::new();
        // The cases that panicked, by hand.
        if case == 16 {
            rows.iter_mut().for_each(|r| r.contact_patch_mm2 = f64::NAN);
            what.push("contact_patch_mm2[..] = NaN".to_string());
        }
        if case == 17 {
            rows.iter_mut().for_each(|r| r.wear_mean_pct = 5e-324);
            what.push("wear_mean_pct[..] = 5e-324".to_string());
        }
        for _ in 0..[1, 2, 5, 30][case % 4] * usize::from(case < 16) {
            let col = columns[rng.random_range(0..columns.len())];
            let v = ABSURD[rng.random_range(0..ABSURD.len())];
            match case % 3 {
                0 => {
                    let i = rng.random_range(0..rows.len());
                    rows[i].set_number(col, v);
                    what.push(format!("{col}[{i}] = {v}"));
                }
                1 => {
                    rows.iter_mut().for_each(|r| {
                        r.set_number(col, v);
                    });
                    what.push(format!("{col}[..] = {v}"));
                }
                _ => {
                    let i = rng.random_range(0..rows.len());
                    let scale = [1e6, 1e-6, -1.0][rng.random_range(0..3)];
                    let x = rows[i].number(col).unwrap() * scale;
                    rows[i].set_number(col, x);
                    what.push(format!("{col}[{i}] × {scale}"));
                }
            }
        }
        let tag = what.join(", ");
        match catch_unwind(AssertUnwindSafe(|| {
            diagnose(&rows, &maps, &Baseline::Physics, &gap)
        })) {
            Err(_) => failures.push(format!("diagnosis panicked: {tag}")),
            Ok(Ok(_)) => diagnosed += 1,
            Ok(Err(_)) => refused += 1,
        }
        for method in [Method::Physical, Method::Pca] {
            let fitted = catch_unwind(AssertUnwindSafe(|| {
                split(&rows, None).and_then(|s| fit_method(method, &s, &settings))
            }));
            if fitted.is_err() {
                failures.push(format!("{method:?} fit panicked: {tag}"));
            }
        }
        for m in &models {
            // A prediction is a finite number or an error (a `note` in predict).
            let predicted = catch_unwind(AssertUnwindSafe(|| {
                rows.iter()
                    .filter_map(|r| m.predict_row(r).ok())
                    .all(f64::is_finite)
            }));
            match predicted {
                Err(_) => failures.push(format!("{} prediction panicked: {tag}", m.method())),
                Ok(false) => failures.push(format!("{} predicted a non-finite: {tag}", m.method())),
                Ok(true) => {}
            }
        }
    }
    println!("absurd KPI values: 18 tables, {diagnosed} diagnosed, {refused} refused");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    // The mutations are not all refused: most tables still diagnose.
    assert!(diagnosed >= 8, "{diagnosed}");
}

/// The byte count a tirewear Parquet file's footer checksum covers.
fn checksummed_bytes(path: &Path) -> u64 {
    use parquet::file::reader::{FileReader, SerializedFileReader};
    let reader = SerializedFileReader::new(std::fs::File::open(path).unwrap()).unwrap();
    let kv = reader
        .metadata()
        .file_metadata()
        .key_value_metadata()
        .cloned();
    let value = kv
        .into_iter()
        .flatten()
        .find(|kv| kv.key == "tirewear.data_crc32")
        .and_then(|kv| kv.value)
        .unwrap_or_else(|| panic!("{} has no data checksum", path.display()));
    value.split(' ').next().unwrap().parse().unwrap()
}

/// One bit flipped inside the data of a Parquet file tirewear wrote (the
/// KPI table, its energy-map, condition-map and road side tables, the
/// simulator's road profiles) is refused by the reader, naming the file.
/// arrow-rs writes no page CRCs: before the footer's checksum such a flip
/// was read as a valid number (a KPI, an energy) as often as not.
#[test]
fn a_bit_flipped_in_a_parquet_file_tirewear_wrote_is_refused_by_name() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    common::demo_kpis(dir.path());
    let kpis = dir.path().join("kpis.parquet");
    type Read = fn(&Path, &Path) -> Result<(), String>;
    let cases: [(&str, Read); 5] = [
        ("kpis.parquet", |_, k| {
            tirewear::kpi::table::read_parquet(k)
                .map(drop)
                .map_err(|e| e.to_string())
        }),
        ("kpis.energy_maps.parquet", |_, k| {
            tirewear::kpi::energy_maps::read_tire_maps(k)
                .map(drop)
                .map_err(|e| e.to_string())
        }),
        ("kpis.condition_maps.parquet", |_, k| {
            tirewear::kpi::energy_maps::read_tire_maps(k)
                .map(drop)
                .map_err(|e| e.to_string())
        }),
        ("kpis.road.parquet", |d, _| {
            let out = d.join("report.html");
            tirewear::report::write_report(d, &out, &[])
                .map(drop)
                .map_err(|e| e.to_string())
        }),
        ("road/profiles.parquet", |d, _| {
            tirewear::ingest::road::read_profiles_parquet(&d.join("road/profiles.parquet"))
                .map(drop)
                .map_err(|e| e.to_string())
        }),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(16);
    for (name, read) in cases {
        let path = dir.path().join(name);
        let clean = std::fs::read(&path).unwrap();
        read(dir.path(), &kpis).unwrap_or_else(|e| panic!("{name} undamaged: {e}"));
        let covered = checksummed_bytes(&path) as usize;
        assert!(covered > clean.len() / 2 && covered < clean.len(), "{name}");
        for _ in 0..6 {
            // Past the leading magic: a flip there is caught by the format.
            let at = rng.random_range(4..covered);
            let mut bytes = clean.clone();
            bytes[at] ^= 1 << rng.random_range(0..8);
            std::fs::write(&path, &bytes).unwrap();
            let e = read(dir.path(), &kpis).expect_err(&format!("{name}, byte {at} flipped"));
            assert!(
                e.contains(name) && e.contains("data checksum"),
                "{name}, byte {at}: {e}"
            );
        }
        std::fs::write(&path, &clean).unwrap();
    }
}
