//! Cross-checks with numpy: numpy reads what this crate writes, and this crate reads what numpy
//! writes (pickled dict meta and `<U` literal meta). Skipped with a message when numpy is not
//! importable, except under CI=true where that is a failure.

mod common;

use evseg_evimo2::{MetaForm, ReadOptions, Sequence, WriteOptions, write_sequence_with};
use evseg_schemas::Distortion;
use serde_json::Value;

/// The Python with numpy ([`evseg_tests::python_with`]), or `None` (skip) outside CI.
fn python() -> Option<String> {
    evseg_tests::python_with(&["numpy"], "numpy cross-checks")
}

fn run(py: &str, script: &str, args: &[&str]) -> String {
    String::from_utf8(evseg_tests::run_python(py, script, args)).expect("utf-8 output")
}

const READ_SCRIPT: &str = r#"
import sys, json, warnings
warnings.simplefilter('error')  # a numpy.core deprecation warning on unpickling fails the test
import numpy as np
d = sys.argv[1]
t = np.load(d + '/dataset_events_t.npy', mmap_mode='r')
xy = np.load(d + '/dataset_events_xy.npy', mmap_mode='r')
p = np.load(d + '/dataset_events_p.npy')
masks = np.load(d + '/dataset_mask.npz')
info = np.load(d + '/dataset_info.npz', allow_pickle=True)
m = info['meta']
meta = m.item() if m.dtype == object else eval(str(m))
top = sorted(meta['imu'].keys())[0]
out = {
    'meta_dtype': str(m.dtype)[:2],
    'n': int(t.shape[0]), 't_dtype': str(t.dtype), 'xy_shape': list(xy.shape), 'xy_dtype': str(xy.dtype),
    'p_shape': list(p.shape), 'p_dtype': str(p.dtype),
    't_sample': [float(v) for v in t[::97]], 'x_sample': [int(v) for v in xy[::89, 0]],
    'y_sample': [int(v) for v in xy[::89, 1]], 'p_sum': int(p.astype(np.int64).sum()),
    'mask_keys': sorted(masks.files),
    'mask_values': [sorted(int(v) for v in np.unique(masks[k])) for k in sorted(masks.files)],
    'mask_count': [[int((masks[k] == v).sum()) for v in (0, 1000, 2000)] for k in sorted(masks.files)],
    'mask_shape': list(masks[masks.files[0]].shape), 'mask_dtype': str(masks[masks.files[0]].dtype),
    'K': info['K'].tolist(), 'D': info['D'].tolist(), 'index_dtype': str(info['index'].dtype),
    'index_first_last': [int(info['index'][0]), int(info['index'][-1])], 'index_len': int(len(info['index'])),
    'discretization': float(info['discretization']),
    'meta_keys': sorted(meta.keys()),
    'intr': [meta['meta'][k] for k in ('fx', 'fy', 'cx', 'cy', 'k1', 'k2', 'k3', 'k4', 'p1', 'p2')],
    'res': [meta['meta']['res_x'], meta['meta']['res_y']], 'dist_model': meta['meta']['dist_model'],
    'frames': [{'id': f['id'], 'ts': f['ts'], 'objects': sorted(k for k in f if k.isdigit()),
                'cam_t': [f['cam']['pos']['t'][a] for a in 'xyz'],
                'obj1_q': [f['1']['pos']['q'][a] for a in 'xyzw']} for f in meta['frames']],
    'traj_len': len(meta['full_trajectory']), 'traj_id': meta['full_trajectory'][0]['id'],
    'traj3': [meta['full_trajectory'][3]['ts']] + [meta['full_trajectory'][3]['cam']['pos']['t'][a] for a in 'xyz'],
    'imu_topics': sorted(meta['imu'].keys()), 'imu_len': len(meta['imu'][top]),
    'imu5': [meta['imu'][top][5]['ts']] + [meta['imu'][top][5]['angular_velocity'][a] for a in 'xyz']
            + [meta['imu'][top][5]['linear_acceleration'][a] for a in 'xyz'],
    'sensor': meta['meta']['evseg_sensor'],
}
print(json.dumps(out))
"#;

fn f(v: &Value) -> f64 {
    v.as_f64().expect("number")
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(f).collect()
}

fn ints(v: &Value) -> Vec<i64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_i64().expect("int"))
        .collect()
}

#[test]
fn numpy_reads_what_we_write() {
    let Some(py) = python() else { return };
    for form in [MetaForm::Pickle, MetaForm::Literal] {
        let dir = tempfile::tempdir().unwrap();
        let data = common::sequence();
        write_sequence_with(
            dir.path(),
            &data,
            &WriteOptions {
                meta_form: form,
                ..WriteOptions::default()
            },
        )
        .unwrap();
        let out: Value =
            serde_json::from_str(&run(&py, READ_SCRIPT, &[dir.path().to_str().unwrap()])).unwrap();
        let ev = &data.events;
        let n = ev.len();
        assert_eq!(
            out["meta_dtype"],
            if form == MetaForm::Pickle { "ob" } else { "<U" }
        );
        assert_eq!(out["n"], n);
        assert_eq!(out["t_dtype"], "float64");
        assert_eq!(out["xy_dtype"], "uint16");
        assert_eq!(out["p_dtype"], "uint8");
        assert_eq!(ints(&out["xy_shape"]), vec![n as i64, 2]);
        assert_eq!(ints(&out["p_shape"]), vec![n as i64]);
        let t: Vec<f64> = ev.t.iter().step_by(97).map(|t| t + common::T_START).collect();
        assert_eq!(floats(&out["t_sample"]), t);
        assert_eq!(
            ints(&out["x_sample"]),
            ev.x.iter().step_by(89).map(|&v| i64::from(v)).collect::<Vec<_>>()
        );
        assert_eq!(
            ints(&out["y_sample"]),
            ev.y.iter().step_by(89).map(|&v| i64::from(v)).collect::<Vec<_>>()
        );
        assert_eq!(out["p_sum"], ev.p.iter().map(|&p| u64::from(p)).sum::<u64>());

        let keys: Vec<&str> = out["mask_keys"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap())
            .collect();
        assert_eq!(
            keys,
            vec!["mask_0000000000", "mask_0000000001", "mask_0000000002"]
        );
        assert_eq!(
            out["mask_values"],
            serde_json::json!([[0, 1000, 2000], [0, 1000], [0, 1000, 2000]])
        );
        for (i, mask) in data.masks.iter().enumerate() {
            let counts: Vec<i64> = (0..3)
                .map(|id| mask.ids.iter().filter(|&&v| v == id).count() as i64)
                .collect();
            assert_eq!(ints(&out["mask_count"][i]), counts);
        }
        assert_eq!(
            ints(&out["mask_shape"]),
            vec![common::HEIGHT as i64, common::WIDTH as i64]
        );
        assert_eq!(out["mask_dtype"], "uint16");

        let cam = &data.camera;
        assert_eq!(
            out["K"],
            serde_json::json!([[cam.fx, 0.0, cam.cx], [0.0, cam.fy, cam.cy], [0.0, 0.0, 1.0]])
        );
        let Distortion::RadTan { k1, k2, p1, p2, k3 } = cam.distortion else {
            panic!()
        };
        assert_eq!(floats(&out["D"]), vec![k1, k2, k3, 0.0]);
        assert_eq!(
            floats(&out["intr"]),
            vec![cam.fx, cam.fy, cam.cx, cam.cy, k1, k2, k3, 0.0, p1, p2]
        );
        assert_eq!(ints(&out["res"]), vec![cam.width as i64, cam.height as i64]);
        assert_eq!(out["dist_model"], "radtan");
        assert_eq!(out["sensor"], cam.sensor.as_str());
        assert_eq!(out["index_dtype"], "uint32");
        assert_eq!(ints(&out["index_first_last"]), vec![0, n as i64 - 1]);
        let span = ev.t[n - 1] - ev.t[0];
        let index_len = out["index_len"].as_i64().unwrap() as f64;
        assert!(
            (index_len - (span / 0.01 + 2.0)).abs() <= 1.0,
            "index length {index_len} for span {span}"
        );
        assert_eq!(f(&out["discretization"]), 0.01);
        assert_eq!(
            out["meta_keys"],
            serde_json::json!(["frames", "full_trajectory", "imu", "meta"])
        );

        let frames = out["frames"].as_array().unwrap();
        assert_eq!(frames.len(), 3);
        for (fj, fr) in frames.iter().zip(&data.frames) {
            assert_eq!(fj["id"].as_u64(), Some(fr.id));
            assert_eq!(f(&fj["ts"]), fr.t + common::T_START);
            let ids: Vec<String> = fr.objects.iter().map(|o| o.id.to_string()).collect();
            assert_eq!(fj["objects"], serde_json::json!(ids));
            assert_eq!(floats(&fj["cam_t"]), fr.camera.unwrap().position.to_vec());
            assert_eq!(floats(&fj["obj1_q"]), fr.objects[0].orientation.to_vec());
        }
        assert_eq!(out["traj_len"], data.camera_poses.len());
        assert_eq!(out["traj_id"].as_u64(), Some(u64::MAX));
        let c3 = &data.camera_poses[3];
        assert_eq!(
            floats(&out["traj3"]),
            vec![
                c3.t + common::T_START,
                c3.position[0],
                c3.position[1],
                c3.position[2]
            ]
        );
        assert_eq!(out["imu_topics"], serde_json::json!(["/prophesee/left/imu"]));
        assert_eq!(out["imu_len"], data.imu.len());
        let s = &data.imu[5];
        let mut imu5 = vec![s.t + common::T_START];
        imu5.extend(s.gyro);
        imu5.extend(s.accel);
        assert_eq!(floats(&out["imu5"]), imu5);
    }
}

/// numpy writes a folder the way EVIMO2's tools do, including real-world details: frame ids not
/// starting at 0, an `rpy` and `classical_frame` key, full_trajectory ids of 2^64 - 1, two IMU
/// topics, `ros_time_offset`, an xy file in npy format 2.0 and a p file in 3.0.
const WRITE_SCRIPT: &str = r#"
import sys
import numpy as np
d, form = sys.argv[1], sys.argv[2]
N = 3000
i = np.arange(N)
t = 100.0 + i * 1e-4
np.save(d + '/dataset_events_t.npy', t)
with open(d + '/dataset_events_xy.npy', 'wb') as fh:
    np.lib.format.write_array(fh, np.stack([(i * 7) % 640, (i * 13) % 480], axis=1).astype(np.uint16), version=(2, 0))
with open(d + '/dataset_events_p.npy', 'wb') as fh:
    np.lib.format.write_array(fh, (i % 2).astype(np.uint8), version=(3, 0))
def pose(k, ts):
    return {'pos': {'q': {'w': 1.0 - 0.01 * k, 'x': 0.1 * k, 'y': -0.2, 'z': 0.3},
                    'rpy': {'p': 0.0, 'r': 0.1, 'y': 0.2},
                    't': {'x': 0.5 * k, 'y': -1.25e-3, 'z': 1.5}}, 'ts': ts}
frames, masks = [], {}
for j, fid in enumerate([10, 11, 12]):
    ts = 100.05 + 0.1 * j
    fr = {'cam': pose(j, ts), '5': pose(j + 1, ts), 'classical_frame': 'img_%d.png' % j,
          'gt_frame': 'depth_mask_%d.png' % fid, 'id': fid, 'ts': ts}
    m = np.zeros((480, 640), dtype=np.uint16)
    m[10:20, 30:50] = 5000
    if j != 1:
        fr['23'] = pose(j + 7, ts)
        m[100:150, 200:260] = 23000
    frames.append(fr)
    masks['mask_%010d' % fid] = m
np.savez_compressed(d + '/dataset_mask.npz', **masks)
traj = [{'cam': pose(k, 100.0 + 0.005 * k), 'gt_frame': 'depth_mask_18446744073709551615.png',
         'id': 18446744073709551615, 'ts': 100.0 + 0.005 * k} for k in range(40)]
imu = {top: [{'angular_velocity': {'x': 0.01 * k + off, 'y': -0.5, 'z': 2e-3},
              'linear_acceleration': {'x': 9.81, 'y': 0.1 * k, 'z': -off}, 'ts': 100.0 + 0.001 * k}
             for k in range(200)]
       for top, off in (('/prophesee/right/imu', 1.0), ('/prophesee/left/imu', 0.0))}
meta = {'frames': frames, 'full_trajectory': traj, 'imu': imu,
        'meta': {'cx': 319.5, 'cy': 239.25, 'dist_model': 'radtan', 'fx': 519.638, 'fy': 519.377,
                 'k1': 0.108537, 'k2': -0.231774, 'k3': 0.0, 'k4': 0.0, 'p1': -0.000183, 'p2': 0.000435,
                 'res_x': 640, 'res_y': 480, 'ros_time_offset': 1606265321.445115}}
K = np.array([[519.638, 0, 319.5], [0, 519.377, 239.25], [0, 0, 1]])
D = np.array([0.108537, -0.231774, 0.0, 0.0])
meta_arr = meta if form == 'pickle' else np.array(str(meta))
np.savez(d + '/dataset_info.npz', index=np.array([0, N - 1], dtype=np.uint32), discretization=0.01,
         K=K, D=D, meta=meta_arr)
print(np.load(d + '/dataset_info.npz', allow_pickle=True)['meta'].dtype)
"#;

#[test]
fn we_read_what_numpy_writes() {
    let Some(py) = python() else { return };
    let mut seqs = Vec::new();
    for form in ["pickle", "literal"] {
        let dir = tempfile::tempdir().unwrap();
        let dtype = run(&py, WRITE_SCRIPT, &[dir.path().to_str().unwrap(), form]);
        let dtype = dtype.trim();
        assert!(
            if form == "pickle" {
                dtype == "object"
            } else {
                dtype.starts_with("<U")
            },
            "{form}: {dtype}"
        );
        let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();

        assert_eq!(seq.t0_s, 100.0);
        let cam = &seq.camera;
        assert_eq!((cam.width, cam.height), (640, 480));
        assert_eq!(
            (cam.fx, cam.fy, cam.cx, cam.cy),
            (519.638, 519.377, 319.5, 239.25)
        );
        assert_eq!(
            cam.distortion,
            Distortion::RadTan {
                k1: 0.108537,
                k2: -0.231774,
                p1: -0.000183,
                p2: 0.000435,
                k3: 0.0
            }
        );
        assert_eq!(cam.imu_to_camera, evseg_evimo2::EVIMO2_IMU_TO_CAMERA);
        assert_eq!(cam.imu_time_offset_s, -0.02);
        assert_eq!(cam.time_origin_us, 100_000_000);
        assert_eq!(cam.sensor, "evimo2");
        assert_eq!(seq.ros_time_offset_s, Some(1606265321.445115));

        // Events: same float operations as numpy: (100.0 + i * 1e-4) - 100.0.
        let mut r = seq.events().unwrap();
        assert_eq!(r.len(), 3000);
        let mut n = 0usize;
        while let Some(c) = r.next_chunk(1000).unwrap() {
            for k in 0..c.len() {
                let i = n + k;
                assert_eq!(c.t[k], (100.0 + i as f64 * 1e-4) - 100.0, "t of event {i}");
                assert_eq!(
                    (c.x[k] as usize, c.y[k] as usize, c.p[k] as usize),
                    ((i * 7) % 640, (i * 13) % 480, i % 2)
                );
            }
            n += c.len();
        }
        assert_eq!(n, 3000);
        assert_eq!(r.non_monotonic(), 0);

        // IMU: the first sorted topic is the left one (offset 0 in the script).
        assert_eq!(
            seq.imu_topics,
            vec!["/prophesee/left/imu", "/prophesee/right/imu"]
        );
        assert_eq!(seq.imu_topic.as_deref(), Some("/prophesee/left/imu"));
        assert_eq!(seq.imu.len(), 200);
        let s = seq.imu[7];
        assert_eq!(s.t, (100.0 + 0.001 * 7.0) - 100.0);
        assert_eq!(s.gyro, [0.01 * 7.0, -0.5, 2e-3]);
        assert_eq!(s.accel, [9.81, 0.1 * 7.0, -0.0]);
        let right = ReadOptions {
            imu_topic: Some("/prophesee/right/imu".into()),
            ..ReadOptions::default()
        };
        let seq_r = Sequence::open(seq.folder.as_path(), &right).unwrap();
        assert_eq!(seq_r.imu[7].gyro[0], 0.01 * 7.0 + 1.0);

        // Poses.
        assert_eq!(seq.camera_poses.len(), 40);
        let c = seq.camera_poses[4];
        assert_eq!(c.t, (100.0 + 0.005 * 4.0) - 100.0);
        assert_eq!(c.position, [0.5 * 4.0, -1.25e-3, 1.5]);
        assert_eq!(c.orientation, [0.1 * 4.0, -0.2, 0.3, 1.0 - 0.01 * 4.0]);
        assert_eq!(
            seq.frames.iter().map(|f| f.id).collect::<Vec<_>>(),
            vec![10, 11, 12]
        );
        let f2 = &seq.frames[2];
        assert_eq!(f2.t, (100.05 + 0.1 * 2.0) - 100.0);
        assert_eq!(f2.objects.iter().map(|o| o.id).collect::<Vec<_>>(), vec![5, 23]);
        assert_eq!(f2.objects[1].position, [0.5 * 9.0, -1.25e-3, 1.5]);
        assert_eq!(seq.frames[1].objects.len(), 1);

        // Masks: frame ids 10..12 map to frame times; values / 1000 are the object ids.
        let mut masks = seq.masks().unwrap();
        assert_eq!(
            masks.entries().iter().map(|e| e.id).collect::<Vec<_>>(),
            vec![10, 11, 12]
        );
        for (k, mask) in masks.iter().enumerate() {
            let mask = mask.unwrap();
            assert_eq!(mask.t, seq.frames[k].t);
            assert_eq!(mask.ids.iter().filter(|&&v| v == 5).count(), 200);
            assert_eq!(
                mask.ids.iter().filter(|&&v| v == 23).count(),
                if k == 1 { 0 } else { 3000 }
            );
            assert_eq!(mask.ids[15 * 640 + 40], 5);
            assert_eq!(
                mask.ids.iter().filter(|&&v| v != 0 && v != 5 && v != 23).count(),
                0
            );
        }
        assert!(seq.depth().unwrap().is_none());
        seqs.push(seq);
    }
    let (a, b) = (&seqs[0], &seqs[1]);
    assert_eq!(
        (&a.camera, &a.imu, &a.camera_poses, &a.frames),
        (&b.camera, &b.imu, &b.camera_poses, &b.frames)
    );
}

/// The numpy-written folder of [`WRITE_SCRIPT`] (pickled meta) after `edit`, a Python
/// script given the folder, rewrote its masks; the folder (kept alive) and its sequence.
fn folder_with_edited_masks(py: &str, edit: &str) -> (tempfile::TempDir, Sequence) {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().to_str().unwrap();
    run(py, WRITE_SCRIPT, &[folder, "pickle"]);
    run(py, edit, &[folder]);
    let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    (dir, seq)
}

/// A folder whose masks hold the object ids themselves (a tool that left out EVIMO2's factor of
/// 1000, written here with numpy) is read with the same ids, and the masks so read are counted:
/// dividing by 1000 would have made every object background, and the run would have had no
/// moving object to score without saying why.
#[test]
fn masks_written_with_raw_object_ids_keep_their_objects() {
    let Some(py) = python() else { return };
    let (_dir, seq) = folder_with_edited_masks(
        &py,
        r#"
import sys, numpy as np
d = sys.argv[1]
z = dict(np.load(d + '/dataset_mask.npz'))
np.savez(d + '/dataset_mask.npz', **{k: (v // 1000).astype(np.uint16) for k, v in z.items()})
"#,
    );
    let mut masks = seq.masks().unwrap();
    assert_eq!(masks.raw_id_masks(), 0);
    for k in 0..masks.len() {
        let mask = masks.read(k).unwrap();
        assert_eq!(mask.ids.iter().filter(|&&v| v == 5).count(), 200, "mask {k}");
        assert_eq!(
            mask.ids.iter().filter(|&&v| v == 23).count(),
            if k == 1 { 0 } else { 3000 },
            "mask {k}"
        );
    }
    assert_eq!(masks.raw_id_masks(), 3);
}

/// A few stray values that are not multiples of 1000 do not turn an EVIMO2 mask into one read
/// with raw ids: most non-zero pixels decide.
#[test]
fn stray_mask_values_do_not_change_the_id_scale() {
    let Some(py) = python() else { return };
    let (_dir, seq) = folder_with_edited_masks(
        &py,
        r#"
import sys, numpy as np
d = sys.argv[1]
z = dict(np.load(d + '/dataset_mask.npz'))
for v in z.values():
    v[0, :3] = 7
np.savez(d + '/dataset_mask.npz', **z)
"#,
    );
    let mut masks = seq.masks().unwrap();
    for k in 0..masks.len() {
        let mask = masks.read(k).unwrap();
        assert_eq!(mask.ids.iter().filter(|&&v| v == 5).count(), 200, "mask {k}");
        assert_eq!(mask.ids[..3], [0, 0, 0], "mask {k}: 7 / 1000");
    }
    assert_eq!(masks.raw_id_masks(), 0);
}
