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
            // The memory need, read from the records' headers by hand
            // before the reader sees the file, must not panic either.
            if std::panic::catch_unwind(|| tirewear::kpi::run_memory_need(&path)).is_err() {
                failures.push(format!("{tag}: the memory need panicked"));
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
            // The report leaves a damaged side table out, naming it.
            let out = d.join("report.html");
            let s = tirewear::report::write_report(d, &out, &[]).map_err(|e| e.to_string())?;
            s.left_out.first().map_or(Ok(()), |e| Err(e.clone()))
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

/// One seeded change of a binary file: bit flips, a 32- or 16-bit
/// little-endian field set to a value that broke readers before, random or
/// zero bytes, bytes cut out, or the file truncated. Most changes land in
/// `hot` (a format's header and index, where a value steers the reader
/// rather than being read as data).
fn mutate_binary(b: &[u8], hot: std::ops::Range<usize>, rng: &mut ChaCha8Rng) -> (Vec<u8>, String) {
    let mut m = b.to_vec();
    let n = m.len();
    let at = |rng: &mut ChaCha8Rng, width: usize| {
        let (lo, hi) = if rng.random_bool(0.8) && hot.end > hot.start + width {
            (hot.start, hot.end - width)
        } else {
            (0, n - width)
        };
        rng.random_range(lo..=hi)
    };
    let what = match rng.random_range(0..7) {
        0 => {
            let mut done = Vec::new();
            for _ in 0..rng.random_range(1..=4) {
                let (i, bit) = (at(rng, 1), rng.random_range(0..8));
                m[i] ^= 1 << bit;
                done.push(format!("{i}.{bit}"));
            }
            format!("bit flips at {}", done.join(","))
        }
        1 => {
            let i = at(rng, 4) & !3;
            let old = u32::from_le_bytes(m[i..i + 4].try_into().unwrap());
            let new = match rng.random_range(0..6) {
                0 => 0,
                1 => u32::MAX - rng.random_range(0..4),
                2 => 1 << rng.random_range(0..32),
                3 => n as u32 + rng.random_range(0..16),
                4 => i as u32,
                _ => old.wrapping_add_signed(rng.random_range(-8..=8)),
            };
            m[i..i + 4].copy_from_slice(&new.to_le_bytes());
            format!("u32 at {i}: {old} -> {new}")
        }
        2 => {
            let i = at(rng, 2) & !1;
            let old = u16::from_le_bytes(m[i..i + 2].try_into().unwrap());
            let new = [0, 1, 2, 3, 4, 5, 6, 7, 8, 0x8000, u16::MAX][rng.random_range(0..11)];
            m[i..i + 2].copy_from_slice(&new.to_le_bytes());
            format!("u16 at {i}: {old} -> {new}")
        }
        3 => {
            let start = at(rng, 1);
            let len = rng.random_range(1..=64).min(n - start);
            rng.fill_bytes(&mut m[start..start + len]);
            format!("{len} random bytes at {start}")
        }
        4 => {
            let start = at(rng, 1);
            let len = rng.random_range(1..=256).min(n - start);
            m[start..start + len].fill(0);
            format!("{len} zero bytes at {start}")
        }
        5 => {
            let start = at(rng, 1);
            let len = rng.random_range(1..=32).min(n - start);
            m.drain(start..start + len);
            format!("{len} bytes removed at {start}")
        }
        _ => {
            let len = at(rng, 1);
            m.truncate(len);
            format!("truncated to {len}")
        }
    };
    (m, what)
}

/// The offsets of a `.ld` file's channel-metadata entries (124 bytes each,
/// linked by the `next` pointer at +4 from the header's pointer at 8).
fn ld_channels(b: &[u8]) -> Vec<usize> {
    let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap()) as usize;
    let (mut at, mut out) = (u32_at(8), Vec::new());
    while at != 0 && at + 124 <= b.len() && out.len() < 10_000 {
        out.push(at);
        at = u32_at(at + 4);
    }
    out
}

/// One seeded change of a `.ld` file: half the time one field of a
/// channel's metadata set to what breaks readers (its `next` pointer back to
/// an earlier channel or past the end, its data pointer, sample count,
/// type, size, rate, scale, offset, multiplier or decimals), else a
/// [`mutate_binary`] change, mostly in the header and channel list.
fn mutate_ld(b: &[u8], rng: &mut ChaCha8Rng) -> (Vec<u8>, String) {
    let channels = ld_channels(b);
    let (first, last) = (channels[0], *channels.last().unwrap());
    if rng.random_bool(0.5) {
        return mutate_binary(b, 0..last + 124, rng);
    }
    let mut m = b.to_vec();
    let k = rng.random_range(0..channels.len());
    let at = channels[k];
    let n = b.len() as u32;
    // (field, offset in the entry, width, values)
    let (field, off, width, value): (&str, usize, usize, u32) = match rng.random_range(0..10) {
        0 => ("next", 4, 4, channels[rng.random_range(0..=k)] as u32),
        1 => (
            "next",
            4,
            4,
            [n, n - 60, u32::MAX, 1][rng.random_range(0..4)],
        ),
        2 => (
            "data",
            8,
            4,
            [n, n - 2, u32::MAX, 0, first as u32][rng.random_range(0..5)],
        ),
        3 => (
            "count",
            12,
            4,
            [u32::MAX, n, 1 << 30, 0, 1][rng.random_range(0..5)],
        ),
        4 => ("type", 18, 2, rng.random_range(0..10)),
        5 => (
            "size",
            20,
            2,
            [0, 1, 2, 3, 4, 8, 0xFFFF][rng.random_range(0..7)],
        ),
        6 => ("rate", 22, 2, [0, 1, 0xFFFF][rng.random_range(0..3)]),
        7 => (
            "offset",
            24,
            2,
            [0x7FFF, 0x8000, 0xFFFF][rng.random_range(0..3)],
        ),
        8 => (
            "mul/scale",
            26 + 2 * rng.random_range(0..2),
            2,
            [0, 0xFFFF][rng.random_range(0..2)],
        ),
        _ => (
            "dec_places",
            30,
            2,
            [0x7FFF, 0x8000, 0xFFFF, 400][rng.random_range(0..4)],
        ),
    };
    m[at + off..at + off + width].copy_from_slice(&value.to_le_bytes()[..width]);
    (
        m,
        format!("channel {k} at {at}: {field} (+{off}) -> {value}"),
    )
}

/// The bytes of a Parquet file's footer (its metadata and length, at the end).
fn parquet_footer(b: &[u8]) -> std::ops::Range<usize> {
    let n = b.len();
    let len = u32::from_le_bytes(b[n - 8..n - 4].try_into().unwrap()) as usize;
    n - 8 - len..n
}

/// A logger table as Parquet, written as another tool would (no tirewear
/// checksum): one Float64 column per channel, named `name [unit]`.
fn write_parquet_log(log: &tirewear::import::log::RawLog, path: &Path) {
    use arrow_array::{ArrayRef, Float64Array, RecordBatch};
    let columns: Vec<(String, ArrayRef)> = log
        .channels
        .iter()
        .map(|c| {
            let name = if c.unit.is_empty() {
                c.name.clone()
            } else {
                format!("{} [{}]", c.name, c.unit)
            };
            let values: ArrayRef = std::sync::Arc::new(Float64Array::from(c.values.clone()));
            (name, values)
        })
        .collect();
    let batch = RecordBatch::try_from_iter(columns).unwrap();
    let file = std::fs::File::create(path).unwrap();
    let mut w = parquet::arrow::ArrowWriter::try_new(file, batch.schema(), None).unwrap();
    w.write(&batch).unwrap();
    w.close().unwrap();
}

type Mutate<'a> = Box<dyn Fn(&mut ChaCha8Rng) -> (Vec<u8>, String) + 'a>;

/// One logger format of [`mutated_logger_files_never_panic_the_import`].
struct LogCase<'a> {
    name: &'static str,
    cases: usize,
    /// The file each case changes: the log, or its sidecar.
    changed: PathBuf,
    /// The log imported, and its run id.
    log: PathBuf,
    run: &'a str,
    /// The undamaged log imported beside it, and its run id.
    good: (&'a Path, &'a str),
    settings: &'a tirewear::import::ImportSettings,
    mutate: Mutate<'a>,
}

/// Damaged logger files never panic `import` and never sink its batch:
/// seeded changes to a MoTeC `.ld` (mostly its header and channel list), a
/// MoTeC CSV, a Parquet log written without tirewear, a `.ldx` sidecar, a
/// `car.toml` and a channel map. Each damaged log is imported beside an
/// undamaged one: the damaged log is imported or refused with its file
/// named, the undamaged one is imported, the manifest stays valid, and one
/// import's heap stays bounded.
#[test]
fn mutated_logger_files_never_panic_the_import() {
    use std::panic::{AssertUnwindSafe, catch_unwind};
    use tirewear::import::{
        CarDescription, ChannelMap, ImportSettings, ImportSummary, NewRun, import_logs,
    };
    use tirewear::ingest::manifest::{Season, TireSets};
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let arch = dir.path().join("season");
    common::simulate_preset(
        tirewear::sim::Preset::Tiny,
        5,
        20.0,
        Some(tirewear::sim::logger::LoggerFormat::MotecLd),
        &arch,
    );
    let logger = arch.join("logger");
    let listed = |ext: &str| {
        let mut v: Vec<PathBuf> = std::fs::read_dir(&logger)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.to_string_lossy().ends_with(ext))
            .collect();
        v.sort();
        v
    };
    let stem = |p: &Path| p.file_stem().unwrap().to_string_lossy().into_owned();
    let (lds, car_files) = (listed(".ld"), listed(".car.toml"));
    let ld_settings = ImportSettings {
        channels: ChannelMap::default_map(),
        cars: car_files
            .iter()
            .map(|p| CarDescription::read(p).unwrap())
            .collect(),
        rate_hz: None,
        calibrate_radius: false,
        new_run: NewRun::default(),
    };
    // The Python-written MoTeC CSV and a Parquet copy of it go in as new runs.
    let compound = Season::open(&arch).unwrap().manifest.compounds[0]
        .id
        .clone();
    let csv_settings = ImportSettings {
        cars: vec![
            CarDescription::read(Path::new(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/datasets/import/car.toml"
            )))
            .unwrap(),
        ],
        new_run: NewRun {
            event: Some("E99-logged".into()),
            track: Some(Season::open(&arch).unwrap().manifest.tracks[0].id.clone()),
            compound: Some(compound),
            tire_sets: Some(TireSets {
                fl: "P1".into(),
                fr: "P2".into(),
                rl: "P3".into(),
                rr: "P4".into(),
            }),
        },
        ..ld_settings.clone()
    };
    let csv = fixture("import/python-motec.csv");
    let pq = dir.path().join("python-motec.parquet");
    write_parquet_log(&tirewear::import::log::read_log(&csv).unwrap(), &pq);

    let work = dir.path().join("damaged");
    std::fs::create_dir_all(&work).unwrap();
    let (mut tried, mut refused, mut imported, mut failures) = (0, 0, 0, Vec::new());
    let mut peak_max = 0;
    // Imports `damaged` (run `run`) beside the undamaged `good` (run
    // `good_run`) and checks the outcome; `named` is the file a refusal
    // must name.
    let mut check = |tag: String,
                     damaged: &Path,
                     run: &str,
                     (good, good_run): (&Path, &str),
                     settings: &ImportSettings,
                     named: &Path,
                     failures: &mut Vec<String>| {
        tried += 1;
        let base = LIVE.load(Ordering::Relaxed);
        PEAK.store(base, Ordering::Relaxed);
        let logs = [damaged.to_path_buf(), good.to_path_buf()];
        let runs = [run.to_string(), good_run.to_string()];
        let r = catch_unwind(AssertUnwindSafe(|| {
            import_logs(&arch, &logs, &runs, settings)
        }));
        let peak = PEAK.load(Ordering::Relaxed).saturating_sub(base);
        peak_max = peak_max.max(peak);
        if peak > MEMORY_BOUND {
            failures.push(format!("{tag}: {peak} bytes of heap"));
        }
        let s: ImportSummary = match r {
            Err(_) => return failures.push(format!("{tag}: panicked")),
            Ok(Err(e)) => return failures.push(format!("{tag}: the batch failed: {e}")),
            Ok(Ok(s)) => s,
        };
        if !s.imported.iter().any(|i| i.log == good) {
            failures.push(format!(
                "{tag}: the undamaged log was not imported: {:?}",
                s.failed
            ));
        }
        match s.failed.iter().find(|(p, _)| p == damaged) {
            // `import` turns a panic into this log's error: still a failure here.
            Some((_, msg)) if msg.contains("internal error") => {
                failures.push(format!("{tag}: panicked inside the import: {msg}"))
            }
            Some((_, msg)) if msg.contains(named.to_str().unwrap()) => refused += 1,
            Some((_, msg)) => failures.push(format!("{tag}: error does not name the file: {msg}")),
            None => imported += 1,
        }
        if let Err(e) = Season::open(&arch) {
            failures.push(format!("{tag}: the manifest no longer reads: {e}"));
        }
    };
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let ld = std::fs::read(&lds[0]).unwrap();
    let ld_target = work.join(lds[0].file_name().unwrap());
    let ld_run = (stem(&lds[0]), stem(&lds[1]));
    // The .ldx sidecar: a valid one, then changed.
    let ldx_text = "<?xml version=\"1.0\"?>\n<LDXFile Version=\"1.6\">\n <Layers>\n  <Layer>\n   \
        <MarkerBlock>\n    <MarkerGroup Name=\"Beacons\" Index=\"3\">\n     \
        <Marker Version=\"100\" ClassName=\"BCN\" Name=\"Manual.1\" Flags=\"77\" Time=\"250000.5\"/>\n     \
        <Marker Version=\"100\" ClassName=\"BCN\" Name=\"Manual.2\" Flags=\"77\" Time=\"1500000\"/>\n    \
        </MarkerGroup>\n   </MarkerBlock>\n  </Layer>\n  <Details>\n   \
        <String Id=\"Total Laps\" Value=\"3\"/>\n  </Details>\n </Layers>\n</LDXFile>\n";
    let csv_text = std::fs::read_to_string(&csv).unwrap();
    let pq_bytes = std::fs::read(&pq).unwrap();
    let logs = [
        // The .ld: its header and channel list take most changes.
        LogCase {
            name: ".ld",
            cases: 160,
            changed: ld_target.clone(),
            log: ld_target.clone(),
            run: &ld_run.0,
            good: (&lds[1], &ld_run.1),
            settings: &ld_settings,
            mutate: Box::new(|rng| mutate_ld(&ld, rng)),
        },
        LogCase {
            name: ".ldx",
            cases: 30,
            changed: ld_target.with_extension("ldx"),
            log: ld_target.clone(),
            run: &ld_run.0,
            good: (&lds[1], &ld_run.1),
            settings: &ld_settings,
            mutate: Box::new(|rng| mutate_text(ldx_text, rng)),
        },
        // The CSV: numbers, lines and the end changed.
        LogCase {
            name: "CSV",
            cases: 60,
            changed: work.join("py.csv"),
            log: work.join("py.csv"),
            run: "py",
            good: (&csv, "py-good"),
            settings: &csv_settings,
            mutate: Box::new(|rng| mutate_text(&csv_text, rng)),
        },
        // The Parquet log: its footer takes most changes.
        LogCase {
            name: "Parquet",
            cases: 60,
            changed: work.join("py.parquet"),
            log: work.join("py.parquet"),
            run: "pq",
            good: (&pq, "pq-good"),
            settings: &csv_settings,
            mutate: Box::new(|rng| mutate_binary(&pq_bytes, parquet_footer(&pq_bytes), rng)),
        },
    ];
    for c in logs {
        std::fs::write(&ld_target, &ld).unwrap();
        for case in 0..c.cases {
            let (bytes, what) = (c.mutate)(&mut rng);
            std::fs::write(&c.changed, &bytes).unwrap();
            let tag = format!("{} case {case} ({what})", c.name);
            check(
                tag,
                &c.log,
                c.run,
                c.good,
                c.settings,
                &c.changed,
                &mut failures,
            );
        }
        std::fs::remove_file(&c.changed).unwrap();
    }
    // The car description and the channel map: refused naming the file, or
    // used for an import that may fail but does not panic.
    let map_path = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/datasets/import/channels.toml"
    ));
    let configs = [
        (car_files[0].clone(), "car.toml"),
        (map_path.to_path_buf(), "channels.toml"),
    ];
    for (original, name) in configs {
        let text = std::fs::read_to_string(&original).unwrap();
        let target = work.join(name);
        for case in 0..30 {
            let (bytes, what) = mutate_text(&text, &mut rng);
            std::fs::write(&target, &bytes).unwrap();
            let tag = format!("{name} case {case} ({what})");
            tried += 1;
            let settings = if name == "car.toml" {
                CarDescription::read(&target).map(|car| ImportSettings {
                    cars: vec![car],
                    ..ld_settings.clone()
                })
            } else {
                ChannelMap::read(&target).map(|channels| ImportSettings {
                    channels,
                    ..ld_settings.clone()
                })
            };
            let settings = match settings {
                Err(e) if e.to_string().contains(target.to_str().unwrap()) => {
                    refused += 1;
                    continue;
                }
                Err(e) => {
                    failures.push(format!("{tag}: error does not name the file: {e}"));
                    continue;
                }
                Ok(s) => s,
            };
            let r = catch_unwind(AssertUnwindSafe(|| {
                import_logs(&arch, &lds[..1], &[stem(&lds[0])], &settings)
            }));
            match r {
                Err(_) => failures.push(format!("{tag}: panicked")),
                Ok(Ok(s)) if s.failed.iter().any(|(_, m)| m.contains("internal error")) => {
                    failures.push(format!("{tag}: panicked inside the import: {:?}", s.failed))
                }
                Ok(_) => imported += 1,
            }
        }
    }
    println!(
        "logger mutations: {tried} tried, {refused} refused with the file named, {imported} \
         imported or used, {} failures; peak heap of one import {peak_max} bytes",
        failures.len()
    );
    assert!(tried >= 370 && refused >= 120, "{tried} {refused}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// `src` rewritten to `dst` as another tool writes it (pyarrow, pandas):
/// the same schema, rows and key/value metadata, but no tirewear data
/// checksum, so a damage is met by the reader itself.
fn foreign_copy(src: &Path, dst: &Path) {
    use parquet::arrow::ArrowWriter;
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let ours = std::fs::File::open(src).unwrap();
    let builder = ParquetRecordBatchReaderBuilder::try_new(ours).unwrap();
    let kv: Vec<_> = builder
        .metadata()
        .file_metadata()
        .key_value_metadata()
        .into_iter()
        .flatten()
        .filter(|kv| kv.key != "tirewear.data_crc32" && kv.key != "ARROW:schema")
        .cloned()
        .collect();
    // The schema's own metadata (a side table's format version) travels in
    // the encoded Arrow schema, which the writer makes again from it.
    let schema = builder.schema().clone();
    let batches: Vec<_> = builder.build().unwrap().map(|b| b.unwrap()).collect();
    let props = parquet::file::properties::WriterProperties::builder()
        .set_key_value_metadata(Some(kv))
        .build();
    let mut w =
        ArrowWriter::try_new(std::fs::File::create(dst).unwrap(), schema, Some(props)).unwrap();
    for b in &batches {
        w.write(b).unwrap();
    }
    w.close().unwrap();
}

/// Damages the Parquet file `clean` (bytes) `cases` times, half of them in
/// its footer, writes each to `target` and reads it with `read`: counts the
/// damages refused naming the file (and among them those where the Parquet
/// decoder panicked, caught by the reader) and those read, and lists every panic,
/// error without the file's name, or read that took more than
/// [`MEMORY_BOUND`] of heap beyond `clean_peak` (the undamaged read's).
fn damage_and_read(
    clean: &[u8],
    target: &Path,
    (seed, cases): (u64, usize),
    clean_peak: usize,
    read: impl Fn(&Path) -> Result<usize, String> + std::panic::RefUnwindSafe,
) -> (Refused, usize, Vec<String>) {
    let footer = parquet_footer(clean);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut refused, mut read_ok, mut failures) = (Refused::default(), 0, Vec::new());
    for case in 0..cases {
        let hot = if case % 2 == 0 {
            footer.clone()
        } else {
            0..clean.len()
        };
        let (m, what) = mutate_binary(clean, hot, &mut rng);
        std::fs::write(target, &m).unwrap();
        let tag = format!("{} case {case} ({what})", target.display());
        let base = LIVE.load(Ordering::Relaxed);
        PEAK.store(base, Ordering::Relaxed);
        let r = std::panic::catch_unwind(|| read(target));
        let peak = PEAK.load(Ordering::Relaxed).saturating_sub(base);
        if peak > clean_peak + MEMORY_BOUND {
            failures.push(format!("{tag}: {peak} bytes of heap"));
        }
        match r {
            Err(_) => failures.push(format!("{tag}: panicked")),
            Ok(Err(e)) if e.contains(target.to_str().unwrap()) => {
                refused.named += 1;
                refused.decoder_panics += usize::from(e.contains("Parquet decoder stopped"));
            }
            Ok(Err(e)) => failures.push(format!("{tag}: error does not name the file: {e}")),
            Ok(Ok(_)) => read_ok += 1,
        }
    }
    (refused, read_ok, failures)
}

/// Damaged files refused with the file named, and how many of those the
/// Parquet decoder panicked on (the reader's error then).
#[derive(Default)]
struct Refused {
    named: usize,
    decoder_panics: usize,
}

/// The heap `read` takes beyond what was live before it.
fn heap_of(read: impl FnOnce()) -> usize {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    read();
    PEAK.load(Ordering::Relaxed).saturating_sub(base)
}

/// A KPI table written by another tool (pyarrow, pandas: no tirewear data
/// checksum) and then damaged is refused naming the file, or read, but never
/// panics the reader or takes unbounded memory: without the checksum the
/// Parquet reader itself meets the damage.
#[test]
fn a_damaged_kpi_table_from_another_tool_never_panics_the_reader() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    common::demo_kpis(dir.path());
    let foreign = dir.path().join("foreign.parquet");
    foreign_copy(&dir.path().join("kpis.parquet"), &foreign);
    let bytes = std::fs::read(&foreign).unwrap();
    let read = |p: &Path| {
        tirewear::kpi::table::read_parquet(p)
            .map(|rows| rows.len())
            .map_err(|e| e.to_string())
    };
    let clean_peak = heap_of(|| assert_eq!(read(&foreign), Ok(320)));
    let target = dir.path().join("damaged.parquet");
    let (refused, read, failures) = damage_and_read(&bytes, &target, (61, 200), clean_peak, read);
    println!(
        "foreign KPI table mutations: {} refused with the file named ({} a decoder panic \
         caught), {read} read, {} failures; undamaged read {clean_peak} bytes of heap",
        refused.named,
        refused.decoder_panics,
        failures.len()
    );
    assert!(refused.named >= 50, "{}", refused.named);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The energy-map and condition-map side tables, written by another tool
/// and then damaged, are refused naming the file, or read, but never panic
/// their readers or take unbounded memory. Their readers index the maps by
/// the file's bin numbers and condition names, which a damage can set to
/// anything.
#[test]
fn damaged_side_tables_from_another_tool_never_panic_their_readers() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    common::demo_kpis(dir.path());
    // Each reader gives the number of tires it read maps for.
    type Read = fn(&Path) -> Result<usize, String>;
    let cases: [(&str, Read); 2] = [
        ("energy_maps", |p| {
            let maps = tirewear::kpi::energy_maps::read_energy_maps(p);
            maps.map(|m| m.len()).map_err(|e| e.to_string())
        }),
        ("condition_maps", |p| {
            let maps = tirewear::kpi::cpu::condition_map::read_condition_maps(p);
            maps.map(|m| m.len()).map_err(|e| e.to_string())
        }),
    ];
    let mut failures = Vec::new();
    for (seed, (name, read)) in (71..).zip(cases) {
        let foreign = dir.path().join(format!("foreign.{name}.parquet"));
        foreign_copy(&dir.path().join(format!("kpis.{name}.parquet")), &foreign);
        let bytes = std::fs::read(&foreign).unwrap();
        // The demo's 320 tire-runs all slid: each has maps.
        let clean_peak = heap_of(|| assert_eq!(read(&foreign), Ok(320), "{name}"));
        let target = dir.path().join(format!("damaged.{name}.parquet"));
        let (refused, read_ok, f) = damage_and_read(&bytes, &target, (seed, 60), clean_peak, read);
        println!(
            "foreign {name} mutations ({} bytes): {} refused with the file named ({} a \
             decoder panic caught), {read_ok} read, {} failures; undamaged read {clean_peak} \
             bytes of heap",
            bytes.len(),
            refused.named,
            refused.decoder_panics,
            f.len()
        );
        assert!(refused.named >= 15, "{name}: {}", refused.named);
        failures.extend(f);
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Every node of a JSON value, as a JSON pointer ("" is the root).
fn json_pointers(v: &serde_json::Value, at: String, out: &mut Vec<String>) {
    out.push(at.clone());
    match v {
        serde_json::Value::Object(m) => {
            for (k, x) in m {
                let key = k.replace('~', "~0").replace('/', "~1");
                json_pointers(x, format!("{at}/{key}"), out);
            }
        }
        serde_json::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                json_pointers(x, format!("{at}/{i}"), out);
            }
        }
        _ => {}
    }
}

/// One seeded change of a JSON file's structure, its checksum field
/// dropped so the change reaches the reader's own checks: a node (of any
/// depth) replaced by a value of another kind or an absurd number, or a
/// member deleted.
fn mutate_json(text: &str, rng: &mut ChaCha8Rng) -> (String, String) {
    let mut v: serde_json::Value = serde_json::from_str(text).unwrap();
    if let Some(m) = v.as_object_mut() {
        m.remove("data_crc32");
    }
    let mut nodes = Vec::new();
    json_pointers(&v, String::new(), &mut nodes);
    let at = nodes[rng.random_range(1..nodes.len())].clone();
    let replacement = match rng.random_range(0..10) {
        0 => serde_json::Value::Null,
        1 => serde_json::json!("x"),
        2 => serde_json::json!(1e308),
        3 => serde_json::json!(-1e308),
        4 => serde_json::json!(0),
        5 => serde_json::json!(-1),
        6 => serde_json::json!([]),
        7 => serde_json::json!({}),
        8 => serde_json::json!(5e-324),
        _ => {
            let (parent, key) = at.rsplit_once('/').unwrap();
            match v.pointer_mut(parent) {
                Some(serde_json::Value::Object(m)) => {
                    m.remove(&key.replace("~1", "/").replace("~0", "~"));
                }
                Some(serde_json::Value::Array(a)) => {
                    a.remove(key.parse::<usize>().unwrap());
                }
                _ => unreachable!("a pointer's parent holds it"),
            }
            return (
                serde_json::to_string_pretty(&v).unwrap(),
                format!("{at} deleted"),
            );
        }
    };
    let what = format!("{at} = {replacement}");
    *v.pointer_mut(&at).unwrap() = replacement;
    (serde_json::to_string_pretty(&v).unwrap(), what)
}

/// The report's optional inputs damaged (models, gap.json, the extraction
/// report, a bench file: their structure changed with the checksum dropped;
/// the road and energy-map tables and a compound: bytes changed) never
/// panic it or sink the page: it is written every time, and each input
/// left out is named with its file.
#[test]
fn damaged_report_inputs_never_panic_or_sink_the_page() {
    use std::panic::{AssertUnwindSafe, catch_unwind};
    use tirewear::model::fit::{FitSettings, Method, fit_method, split};
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let rows = common::demo_kpis(d);
    let s = split(&rows, None).unwrap();
    let models: Vec<_> = [Method::Physical, Method::Pca]
        .into_iter()
        .map(|m| fit_method(m, &s, &FitSettings::default()).unwrap().0)
        .collect();
    tirewear::model::saved::save_all(&models, &d.join("models")).unwrap();
    use tirewear::gap::report::{Baseline, GapSettings, diagnose_file, write_diagnosis};
    let gap = GapSettings {
        wlf: tirewear::ingest::compound::read_wlf(&d.join("compounds")).unwrap(),
        ..Default::default()
    };
    let diagnosis = diagnose_file(&d.join("kpis.parquet"), &Baseline::Physics, &gap).unwrap();
    write_diagnosis(&diagnosis, &d.join("gap")).unwrap();
    std::fs::write(
        d.join("bench.json"),
        r#"{"cpu": "CPU", "gpu": null, "threads": 2, "lines": [
            {"kernel": "energy_map", "size": "1 M samples", "engine": "cpu, 1 thread",
             "seconds": 0.004, "vs_memory_pass": 0.5, "reference": "memory pass"},
            {"kernel": "decode, block", "size": "80 runs", "engine": "tirewear, 1 thread",
             "seconds": 0.3, "vs_memory_pass": 0.73, "reference": "zstd only"}]}"#,
    )
    .unwrap();
    let compound = std::fs::read_dir(d.join("compounds"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "toml"))
        .unwrap();
    let compound = compound
        .strip_prefix(d)
        .unwrap()
        .to_str()
        .unwrap()
        .to_string();
    let out = d.join("report.html");
    let clean = tirewear::report::write_report(d, &out, &[]).unwrap();
    assert!(clean.left_out.is_empty(), "{:?}", clean.left_out);

    let json_inputs = [
        "models/physical.json",
        "models/pca.json",
        "gap/gap.json",
        "kpis.report.json",
        "bench.json",
    ];
    let byte_inputs = [
        "kpis.road.parquet",
        "kpis.energy_maps.parquet",
        compound.as_str(),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(30);
    let (mut tried, mut left_out, mut drawn) = (0, 0, 0);
    let mut failures = Vec::new();
    for name in json_inputs.iter().chain(&byte_inputs) {
        let path = d.join(name);
        let original = std::fs::read(&path).unwrap();
        let cases = if json_inputs.contains(name) { 24 } else { 8 };
        for _ in 0..cases {
            let (bytes, what) = if json_inputs.contains(name) {
                let (t, w) = mutate_json(std::str::from_utf8(&original).unwrap(), &mut rng);
                (t.into_bytes(), w)
            } else if name.ends_with(".toml") {
                mutate_text(std::str::from_utf8(&original).unwrap(), &mut rng)
            } else {
                mutate_binary(&original, 0..original.len(), &mut rng)
            };
            std::fs::write(&path, &bytes).unwrap();
            tried += 1;
            let tag = format!("{name}: {what}");
            match catch_unwind(AssertUnwindSafe(|| {
                tirewear::report::write_report(d, &out, &[])
            })) {
                Err(_) => failures.push(format!("{tag}: panicked")),
                Ok(Err(e)) => failures.push(format!("{tag}: no page: {e}")),
                Ok(Ok(s)) => {
                    let file = Path::new(name).file_name().unwrap().to_str().unwrap();
                    if s.left_out.is_empty() {
                        drawn += 1;
                    } else if s.left_out.iter().all(|e| e.contains(file)) {
                        left_out += 1;
                    } else {
                        failures.push(format!(
                            "{tag}: left out without the file: {:?}",
                            s.left_out
                        ));
                    }
                }
            }
        }
        std::fs::write(&path, &original).unwrap();
    }
    println!(
        "report inputs: {tried} damaged, {left_out} left out and named, {drawn} drawn with the \
         changed values, {} failures",
        failures.len()
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(left_out >= tried / 5, "{left_out} of {tried}");
}

/// Heap of a whole `extract` of `season`, runs one at a time (a budget of
/// the largest run's need admits no second run beside it), and that need.
fn extract_peak(season: &Path, out: &Path) -> (usize, u64) {
    use tirewear::kpi::{ExtractOptions, extract};
    let (_, need, _) =
        common::hungriest_run(&tirewear::ingest::manifest::Season::open(season).unwrap());
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let s = extract(&ExtractOptions {
        memory_limit: tirewear::memory::MemoryLimit::Bytes(need),
        ..ExtractOptions::new(season, out)
    })
    .unwrap();
    let peak = PEAK.load(Ordering::Relaxed).saturating_sub(base);
    assert!(s.skipped.is_empty(), "{:?}", s.skipped);
    (peak, need)
}

/// `run_memory_need` against the heap measured by this binary's counting
/// allocator: a season's extraction at 1000 Hz (block form) and at 250 Hz
/// (per-sample form), runs one at a time, takes no more heap above the
/// same season's at 5 Hz (every run tiny: what the extraction needs
/// beside its runs) than its largest run's estimated need; and the
/// estimate is not wasteful for blocks, the densest form (within 1.5× of
/// what the run took).
#[test]
fn a_runs_memory_need_bounds_its_peak_heap() {
    use tirewear::ingest::telemetry::Encoding;
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let season = |name: &str, encoding, rate_hz| {
        let out = dir.path().join(name);
        common::simulate_encoded(
            tirewear::sim::Preset::Tiny,
            3,
            rate_hz,
            encoding,
            None,
            &out,
        );
        let (peak, need) = extract_peak(&out, &out.join("kpis.parquet"));
        eprintln!("{name}: peak heap {peak} B, largest run's need {need} B");
        (peak as u64, need)
    };
    let (base, _) = season("base", Encoding::Block, 5.0);
    for (name, encoding, rate, wasteful) in [
        ("block", Encoding::Block, 1000.0, true),
        ("sample", Encoding::Sample, 250.0, false),
    ] {
        let (peak, need) = season(name, encoding, rate);
        let run_peak = peak.saturating_sub(base);
        assert!(
            run_peak <= need,
            "{name}: a run took {run_peak} B of heap, more than its estimated need {need} B"
        );
        if wasteful {
            assert!(
                need as f64 <= 1.5 * run_peak as f64,
                "{name}: the estimated need {need} B is over 1.5x the {run_peak} B a run took"
            );
        }
    }
}

/// Another tool's table (no checksum) whose data make the Parquet decoder
/// panic — eleven `0xff` over a dictionary column, the first place that
/// panics the bare reader, where it reads a run-length header — is the
/// file's error: from the library, and from the command line, which does
/// not print the caught panic as a crash (`fit` exits 1 with the file's
/// error, carrying the panic's message and place; no "panicked at").
#[test]
fn a_decoder_panic_reaches_the_user_as_the_files_error_not_a_crash() {
    use arrow_array::{RecordBatch, StringArray};
    use parquet::arrow::ArrowWriter;
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let wheels = ["FL", "FR", "RL", "RR"];
    let wheels = StringArray::from_iter_values((0..400).map(|i| wheels[i % 4]));
    let batch = RecordBatch::try_from_iter([("wheel", std::sync::Arc::new(wheels) as _)]).unwrap();
    let mut clean = Vec::new();
    let mut w = ArrowWriter::try_new(&mut clean, batch.schema(), None).unwrap();
    w.write(&batch).unwrap();
    w.close().unwrap();
    let data_end = parquet_footer(&clean).start;
    let panics = |b: &[u8]| {
        std::panic::catch_unwind(|| {
            let bytes = bytes::Bytes::copy_from_slice(b);
            let Ok(reader) =
                ParquetRecordBatchReaderBuilder::try_new(bytes).and_then(|r| r.build())
            else {
                return;
            };
            // Up to the first error: the reader gives errors without end.
            reader.take_while(Result::is_ok).for_each(drop);
        })
        .is_err()
    };
    let damaged = (4..data_end - 11)
        .map(|at| {
            let mut b = clean.clone();
            b[at..at + 11].fill(0xff);
            b
        })
        .find(|b| panics(b))
        .expect("some place where the decoder panics");
    let dir = tempfile::tempdir().unwrap();
    let kpis = dir.path().join("kpis.parquet");
    std::fs::write(&kpis, &damaged).unwrap();
    let e = tirewear::kpi::table::read_parquet(&kpis)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(kpis.to_str().unwrap())
            && e.contains("damaged data: the Parquet decoder stopped on it"),
        "{e}"
    );
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_tirewear"))
        .args(["--quiet", "fit"])
        .arg(&kpis)
        .arg("--out")
        .arg(dir.path().join("models"))
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(!stderr.contains("panicked at"), "{stderr}");
    let error = stderr
        .lines()
        .find(|l| l.starts_with("Error:"))
        .unwrap_or_default();
    assert!(
        error.contains(kpis.to_str().unwrap())
            && error.contains("damaged data: the Parquet decoder stopped on it")
            && error.contains(", at ")
            && error.contains(".rs:"),
        "{stderr}"
    );
}
