// Telemetry reduction (paper table 4): per-sample slip, sliding velocities and
// friction power, reduced per chunk of one wheel into SUMS partial sums.
// CPU twin: src/kpi/cpu/telemetry_reduce.rs (same workgroup size, items per
// thread, sum order and tree); partials are merged per wheel in f64 on the CPU.

// shared.wgsl (prepended by the host): WG_SIZE, ITEMS, Sample, Chunk.

// Must match src/kpi/cpu/telemetry_reduce.rs: SUMS, CARCASS_PRESSURE_PA (checked by tests/shader_contract.rs).
const SUMS: u32 = 22u;
const CARCASS_PRESSURE_PA: f32 = 40000.0;

// Must match ReduceRef (checked by tests/shader_contract.rs).
struct Reference {
    v: array<f32, 8>,
}

@group(0) @binding(0) var<storage, read> samples: array<Sample>;
@group(0) @binding(1) var<storage, read> chunks: array<Chunk>;
@group(0) @binding(2) var<storage, read> refs: array<Reference>;
@group(0) @binding(3) var<storage, read_write> partials: array<f32>;

var<workgroup> acc: array<array<f32, SUMS>, WG_SIZE>;

@compute @workgroup_size(WG_SIZE)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    // Dispatches over 65 535 workgroups use a 2-D grid.
    let c_index = wg.x + wg.y * nwg.x;
    let in_range = c_index < arrayLength(&chunks);
    var s: array<f32, SUMS>;
    if in_range {
        let chunk = chunks[c_index];
        let r = refs[chunk.wheel].v;
        for (var k = 0u; k < ITEMS; k++) {
            let j = lid + k * WG_SIZE; // coalesced
            if j < chunk.count {
                let p = samples[chunk.start + j];
                let v_sx = p.vx - p.omega * p.radius; // eq. 21
                let v_sy = p.vy; // eq. 22
                let p_x = -p.fx * v_sx; // eq. 23, dissipation sign
                let p_y = -p.fy * v_sy; // eq. 24
                let v_s = sqrt(v_sx * v_sx + v_sy * v_sy);
                var q = array<f32, 7>(
                    p.t_surface - r[0],
                    p.t_inner - r[1],
                    p.fx - r[2],
                    p.fy - r[3],
                    p.fz - r[4],
                    abs(v_sx) - r[5],
                    abs(v_sy) - r[6],
                );
                for (var m = 0u; m < 7u; m++) {
                    s[m] += q[m];
                    s[7u + m] += q[m] * q[m];
                }
                s[14] += p_x * p.dt;
                s[15] += p_y * p.dt;
                s[16] += v_s * p.dt;
                s[17] += p.dt;
                s[18] += p.camber;
                s[19] += p.pressure;
                s[20] += p.fz / (p.pressure + CARCASS_PRESSURE_PA) * 1e6;
                s[21] += 1.0;
            }
        }
    }
    acc[lid] = s;
    workgroupBarrier();
    for (var stride = WG_SIZE / 2u; stride > 0u; stride = stride / 2u) {
        if lid < stride {
            for (var m = 0u; m < SUMS; m++) {
                acc[lid][m] += acc[lid + stride][m];
            }
        }
        workgroupBarrier();
    }
    if in_range && lid == 0u {
        for (var m = 0u; m < SUMS; m++) {
            partials[c_index * SUMS + m] = acc[0][m];
        }
    }
}
