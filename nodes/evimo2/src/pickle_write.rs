//! Writes the pickle numpy produces for `np.save(path, np.array(obj, dtype=object))` — a 0-d object
//! array holding one Python value — so `np.load(path, allow_pickle=True).item()` returns `obj`.
//!
//! The opcodes are those of pickle protocol 3 (plus `GLOBAL`, valid in every protocol). The array is
//! rebuilt through `numpy.core.multiarray._reconstruct(numpy.ndarray, (0,), b'b')` followed by
//! `__setstate__((1, (), dtype('O8'), False, [obj]))`, the form numpy 1.x writes; numpy 2.x keeps
//! `numpy.core.multiarray._reconstruct` importable for exactly these pickles.

use crate::pylit::PyValue;

// Pickle opcodes (CPython Lib/pickle.py names).
const PROTO: u8 = 0x80;
const STOP: u8 = b'.';
const GLOBAL: u8 = b'c';
const REDUCE: u8 = b'R';
const BUILD: u8 = b'b';
const MARK: u8 = b'(';
const TUPLE: u8 = b't';
const TUPLE1: u8 = 0x85;
const TUPLE3: u8 = 0x87;
const EMPTY_TUPLE: u8 = b')';
const EMPTY_LIST: u8 = b']';
const APPEND: u8 = b'a';
const APPENDS: u8 = b'e';
const EMPTY_DICT: u8 = b'}';
const SETITEMS: u8 = b'u';
const NONE: u8 = b'N';
const NEWTRUE: u8 = 0x88;
const NEWFALSE: u8 = 0x89;
const BININT: u8 = b'J';
const BININT1: u8 = b'K';
const LONG1: u8 = 0x8a;
const BINFLOAT: u8 = b'G';
const BINUNICODE: u8 = b'X';
const SHORT_BINBYTES: u8 = b'C';
const BINBYTES: u8 = b'B';

/// Items per `APPENDS`/`SETITEMS` batch, as CPython's pickler batches them.
const BATCH: usize = 1000;

/// The pickle of a 0-d numpy object array holding `value` (the data part of an `|O` `.npy`).
pub fn numpy_object_scalar(value: &PyValue) -> Vec<u8> {
    let mut out = vec![PROTO, 3];
    global(&mut out, "numpy.core.multiarray", "_reconstruct");
    global(&mut out, "numpy", "ndarray");
    out.extend_from_slice(&[BININT1, 0, TUPLE1, SHORT_BINBYTES, 1, b'b', TUPLE3, REDUCE]);
    // State tuple: (version 1, shape (), dtype, is_fortran False, [value]).
    out.extend_from_slice(&[MARK, BININT1, 1, EMPTY_TUPLE]);
    global(&mut out, "numpy", "dtype");
    unicode(&mut out, "O8");
    out.extend_from_slice(&[NEWFALSE, NEWTRUE, TUPLE3, REDUCE]);
    // dtype state: (3, '|', None, None, None, -1, -1, 63) — 63 = NPY_OBJECT_DTYPE_FLAGS.
    out.extend_from_slice(&[MARK, BININT1, 3]);
    unicode(&mut out, "|");
    out.extend_from_slice(&[NONE, NONE, NONE]);
    int(&mut out, -1);
    int(&mut out, -1);
    int(&mut out, 63);
    out.extend_from_slice(&[TUPLE, BUILD]);
    out.extend_from_slice(&[NEWFALSE, EMPTY_LIST]);
    value_into(&mut out, value);
    out.extend_from_slice(&[APPEND, TUPLE, BUILD, STOP]);
    out
}

/// The pickle of a plain Python value (protocol 3).
pub fn plain(value: &PyValue) -> Vec<u8> {
    let mut out = vec![PROTO, 3];
    value_into(&mut out, value);
    out.push(STOP);
    out
}

fn global(out: &mut Vec<u8>, module: &str, name: &str) {
    out.push(GLOBAL);
    out.extend_from_slice(module.as_bytes());
    out.push(b'\n');
    out.extend_from_slice(name.as_bytes());
    out.push(b'\n');
}

fn unicode(out: &mut Vec<u8>, s: &str) {
    out.push(BINUNICODE);
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

fn int(out: &mut Vec<u8>, v: i128) {
    if (0..=255).contains(&v) {
        out.extend_from_slice(&[BININT1, v as u8]);
    } else if let Ok(small) = i32::try_from(v) {
        out.push(BININT);
        out.extend_from_slice(&small.to_le_bytes());
    } else {
        // Minimal two's-complement little-endian bytes, as Python's encode_long.
        let mut bytes = v.to_le_bytes().to_vec();
        while bytes.len() > 1 {
            let last = bytes[bytes.len() - 1];
            let sign_of_prev = bytes[bytes.len() - 2] & 0x80;
            if (last == 0 && sign_of_prev == 0) || (last == 0xff && sign_of_prev != 0) {
                bytes.pop();
            } else {
                break;
            }
        }
        out.extend_from_slice(&[LONG1, bytes.len() as u8]);
        out.extend_from_slice(&bytes);
    }
}

fn value_into(out: &mut Vec<u8>, value: &PyValue) {
    match value {
        PyValue::None => out.push(NONE),
        PyValue::Bool(true) => out.push(NEWTRUE),
        PyValue::Bool(false) => out.push(NEWFALSE),
        PyValue::Int(i) => int(out, *i),
        PyValue::Float(f) => {
            out.push(BINFLOAT);
            out.extend_from_slice(&f.to_be_bytes());
        }
        PyValue::Str(s) => unicode(out, s),
        PyValue::Bytes(b) => {
            if b.len() < 256 {
                out.extend_from_slice(&[SHORT_BINBYTES, b.len() as u8]);
            } else {
                out.push(BINBYTES);
                out.extend_from_slice(&(b.len() as u32).to_le_bytes());
            }
            out.extend_from_slice(b);
        }
        PyValue::List(items) => {
            out.push(EMPTY_LIST);
            for batch in items.chunks(BATCH) {
                out.push(MARK);
                for item in batch {
                    value_into(out, item);
                }
                out.push(APPENDS);
            }
        }
        PyValue::Tuple(items) => {
            if items.is_empty() {
                out.push(EMPTY_TUPLE);
            } else {
                out.push(MARK);
                for item in items {
                    value_into(out, item);
                }
                out.push(TUPLE);
            }
        }
        PyValue::Dict(items) => {
            out.push(EMPTY_DICT);
            for batch in items.chunks(BATCH) {
                out.push(MARK);
                for (k, v) in batch {
                    value_into(out, k);
                    value_into(out, v);
                }
                out.push(SETITEMS);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_encoding_matches_python() {
        // pickle.dumps(18446744073709551615, 3) == b'\x80\x03\x8a\t\xff\xff\xff\xff\xff\xff\xff\xff\x00.'
        let p = plain(&PyValue::Int(18446744073709551615));
        assert_eq!(p, b"\x80\x03\x8a\x09\xff\xff\xff\xff\xff\xff\xff\xff\x00.");
        // pickle.dumps(-2**40, 3) == b'\x80\x03\x8a\x06\x00\x00\x00\x00\x00\xff.'
        let p = plain(&PyValue::Int(-(1i128 << 40)));
        assert_eq!(p, b"\x80\x03\x8a\x06\x00\x00\x00\x00\x00\xff.");
        // pickle.dumps(-1, 3) == b'\x80\x03J\xff\xff\xff\xff.'
        assert_eq!(plain(&PyValue::Int(-1)), b"\x80\x03J\xff\xff\xff\xff.");
    }

    #[test]
    fn dict_and_float_encoding_matches_python() {
        // pickle.dumps({'a': 1.5, 'b': [None, True]}, 3) — CPython adds BINPUT memo opcodes; the
        // rest is identical, checked here against the opcode sequence without them.
        let v = PyValue::Dict(vec![
            (PyValue::Str("a".into()), PyValue::Float(1.5)),
            (
                PyValue::Str("b".into()),
                PyValue::List(vec![PyValue::None, PyValue::Bool(true)]),
            ),
        ]);
        let mut expected = b"\x80\x03}(X\x01\x00\x00\x00aG".to_vec();
        expected.extend_from_slice(&1.5f64.to_be_bytes());
        expected.extend_from_slice(b"X\x01\x00\x00\x00b](N\x88eu.");
        assert_eq!(plain(&v), expected);
    }

    #[test]
    fn serde_pickle_reads_the_object_array() {
        let dict = PyValue::Dict(vec![(PyValue::Str("k".into()), PyValue::Int(7))]);
        let p = numpy_object_scalar(&dict);
        let v =
            serde_pickle::value_from_slice(&p, serde_pickle::DeOptions::new().replace_unresolved_globals())
                .unwrap();
        let serde_pickle::Value::Tuple(state) = v else {
            panic!("state is not a tuple: {v:?}")
        };
        assert_eq!(state.len(), 5);
        let serde_pickle::Value::List(items) = &state[4] else {
            panic!("no list")
        };
        assert_eq!(items.len(), 1);
        assert!(matches!(&items[0], serde_pickle::Value::Dict(d) if d.len() == 1));
    }
}
