//! Deserialisers of one field's value each (a number, a count, a per-ray array, a pose, a
//! timestamp, ...), whose errors say what was wrong and, in arrays, at which index.

use crate::formats::limits;
use crate::geometry::Pose;
use crate::scan::{Hit, Timestamp};
use serde::Deserialize;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use std::fmt;

/// Prefixes an error from inside a field's value with the field's name: `readings[3]: ...`
/// for element errors (which start with `[i]`), `readings: ...` otherwise.
pub(super) fn in_field<E: de::Error>(field: &str, e: E) -> E {
    let text = e.to_string();
    // serde_json has already placed the inner error; its position is added again outside.
    let text = match text.rfind(" at line ") {
        Some(i) => &text[..i],
        None => &text[..],
    };
    if text.starts_with('[') {
        E::custom(format!("{field}{text}"))
    } else {
        E::custom(format!("{field}: {text}"))
    }
}

/// Types that are read as a value of one JSON field.
pub(super) trait Value: Sized {
    type Out;
    fn into_out(self) -> Self::Out;
}

/// A field or element that may be `null`.
pub(super) struct Opt<T>(pub(super) Option<T>);

impl<T: Value> Opt<T> {
    pub(super) fn get(self) -> Option<T::Out> {
        self.0.map(Value::into_out)
    }
}

impl<T: Value> Value for Opt<T> {
    type Out = Option<T::Out>;
    fn into_out(self) -> Self::Out {
        self.get()
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Opt<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Option::<T>::deserialize(d).map(Opt)
    }
}

/// A JSON number of any kind, as f64.
pub(super) struct Num(pub(super) f64);

impl Value for Num {
    type Out = f64;
    fn into_out(self) -> f64 {
        self.0
    }
}

struct NumVisitor;

impl Visitor<'_> for NumVisitor {
    type Value = f64;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number")
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<f64, E> {
        Ok(v)
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<f64, E> {
        Ok(v as f64)
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<f64, E> {
        Ok(v as f64)
    }
}

impl<'de> Deserialize<'de> for Num {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_f64(NumVisitor).map(Num)
    }
}

/// An integer >= 0 (a float with no fraction is accepted: some writers emit `3.0`).
pub(super) struct Count(pub(super) u64);

impl Value for Count {
    type Out = u64;
    fn into_out(self) -> u64 {
        self.0
    }
}

impl<'de> Deserialize<'de> for Count {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(CountVisitor("an integer >= 0"))
            .map(Count)
    }
}

/// A count of rays, worded as what it must be, a positive integer, so that `-3` and `0`
/// (refused by [`limits::check_rays`]) get the same words. Read as [`Count`].
pub(super) struct RayCount(pub(super) u64);

impl Value for RayCount {
    type Out = u64;
    fn into_out(self) -> u64 {
        self.0
    }
}

impl<'de> Deserialize<'de> for RayCount {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(CountVisitor("a positive integer"))
            .map(RayCount)
    }
}

/// Reads a whole number >= 0; `.0` says what it must be, in errors.
struct CountVisitor(&'static str);

impl Visitor<'_> for CountVisitor {
    type Value = u64;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(self.0)
    }
    fn visit_u64<E: de::Error>(self, v: u64) -> Result<u64, E> {
        Ok(v)
    }
    fn visit_i64<E: de::Error>(self, v: i64) -> Result<u64, E> {
        u64::try_from(v).map_err(|_| E::custom(format!("must be {}, not {v}", self.0)))
    }
    fn visit_f64<E: de::Error>(self, v: f64) -> Result<u64, E> {
        // 2^53: beyond it a float no longer says which integer it is.
        if v >= 0.0 && v.fract() == 0.0 && v <= 9_007_199_254_740_992.0 {
            Ok(v as u64)
        } else {
            Err(E::custom(format!("must be {}, not {v}", self.0)))
        }
    }
}

/// A per-ray array; element errors say which index.
pub(super) struct Array<T>(pub(super) Vec<T>);

impl<T: Value> Value for Array<T> {
    type Out = Vec<T::Out>;
    fn into_out(self) -> Self::Out {
        self.0.into_iter().map(Value::into_out).collect()
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Array<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V<T> {
            type Value = Vec<T>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an array")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Vec<T>, A::Error> {
                let mut out = Vec::with_capacity(seq.size_hint().unwrap_or(256).min(1 << 16));
                each_element(seq, |v| out.push(v))?;
                Ok(out)
            }
        }
        d.deserialize_seq(V(std::marker::PhantomData)).map(Array)
    }
}

/// Reads every element of a JSON array as a `T`, handing each to `f`; an element's error
/// names its index (`[i]: ...`).
fn each_element<'de, A: SeqAccess<'de>, T: Deserialize<'de>>(
    mut seq: A,
    mut f: impl FnMut(T),
) -> Result<(), A::Error> {
    let mut i = 0;
    loop {
        match seq.next_element::<T>() {
            // Bounds the memory of one line whatever its length.
            Ok(Some(_)) if i == limits::MAX_RAYS => {
                return Err(de::Error::custom(format!(
                    "more than {} entries, the limit of rays per scan",
                    limits::MAX_RAYS
                )));
            }
            Ok(Some(v)) => f(v),
            Ok(None) => return Ok(()),
            Err(e) => return Err(in_field(&format!("[{i}]"), e)),
        }
        i += 1;
    }
}

/// A `valid` entry: 0 or 1 (booleans are accepted too).
pub(super) struct Flag(pub(super) bool);

impl Value for Flag {
    type Out = bool;
    fn into_out(self) -> bool {
        self.0
    }
}

impl<'de> Deserialize<'de> for Flag {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = bool;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("0 or 1")
            }
            fn visit_bool<E: de::Error>(self, v: bool) -> Result<bool, E> {
                Ok(v)
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<bool, E> {
                match v {
                    0 => Ok(false),
                    1 => Ok(true),
                    _ => Err(E::custom(format!("must be 0 or 1, not {v}"))),
                }
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<bool, E> {
                Err(E::custom(format!("must be 0 or 1, not {v}")))
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<bool, E> {
                match v {
                    0.0 => Ok(false),
                    1.0 => Ok(true),
                    _ => Err(E::custom(format!("must be 0 or 1, not {v}"))),
                }
            }
        }
        d.deserialize_any(V).map(Flag)
    }
}

/// A `hit` entry: 0 nothing, 1 wall, 2 floor, 3 ceiling.
pub(super) struct HitCode(pub(super) Hit);

impl Value for HitCode {
    type Out = Hit;
    fn into_out(self) -> Hit {
        self.0
    }
}

impl<'de> Deserialize<'de> for HitCode {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let Count(code) = Count::deserialize(d)?;
        Hit::from_code(code)
            .map(HitCode)
            .ok_or_else(|| de::Error::custom(format!("must be 0, 1, 2 or 3, not {code}")))
    }
}

/// A `hit` array checked entry by entry (as [`HitCode`]s) and counted, but not kept: `level`
/// never reads the labels, yet a bad one is still bad input.
pub(super) struct HitLen(pub(super) Option<usize>);

impl<'de> Deserialize<'de> for HitLen {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = HitLen;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an array or null")
            }
            fn visit_unit<E: de::Error>(self) -> Result<HitLen, E> {
                Ok(HitLen(None))
            }
            fn visit_none<E: de::Error>(self) -> Result<HitLen, E> {
                Ok(HitLen(None))
            }
            fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<HitLen, D::Error> {
                d.deserialize_seq(V)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<HitLen, A::Error> {
                let mut n = 0;
                each_element(seq, |_: HitCode| n += 1)?;
                Ok(HitLen(Some(n)))
            }
        }
        d.deserialize_option(V)
    }
}

/// A pose: 6 numbers `[x, y, z, rz, ry, rx]` or 3 `[x, y, rz]`; `null`, or any `null` entry,
/// means unknown (CSM writes `[null, null, null]`).
pub(super) struct PoseField(pub(super) Option<Pose>);

impl<'de> Deserialize<'de> for PoseField {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let Some(Array(v)) = Option::<Array<Opt<Num>>>::deserialize(d)? else {
            return Ok(PoseField(None));
        };
        if v.len() != 3 && v.len() != 6 {
            return Err(de::Error::custom(format!(
                "a pose has 6 numbers [x, y, z, rz, ry, rx] or 3 [x, y, rz], not {}",
                v.len()
            )));
        }
        let nums: Option<Vec<f64>> = v.into_iter().map(|o| o.0.map(|n| n.0)).collect();
        Ok(PoseField(nums.map(|n| match n[..] {
            [x, y, rz] => Pose::planar(x, y, rz),
            _ => Pose::new(n[0], n[1], n[2], n[3], n[4], n[5]),
        })))
    }
}

/// A timestamp `[sec, usec]` (CSM), or seconds as one number.
pub(super) struct Stamp(pub(super) Timestamp);

impl Value for Stamp {
    type Out = Timestamp;
    fn into_out(self) -> Timestamp {
        self.0
    }
}

impl<'de> Deserialize<'de> for Stamp {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Timestamp;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("[sec, usec]")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Timestamp, A::Error> {
                let whole = |v: f64| -> Result<i64, A::Error> {
                    if v.fract() == 0.0 && v.abs() < 9e15 {
                        Ok(v as i64)
                    } else {
                        Err(de::Error::custom(format!(
                            "timestamp must be [sec, usec] integers, not {v}"
                        )))
                    }
                };
                let sec = seq.next_element::<Num>()?;
                let usec = seq.next_element::<Num>()?;
                match (sec, usec, seq.next_element::<serde_json::Value>()?) {
                    (Some(Num(s)), Some(Num(u)), None) => Ok(Timestamp {
                        sec: whole(s)?,
                        usec: whole(u)?,
                    }),
                    _ => Err(de::Error::custom("must be [sec, usec]")),
                }
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Timestamp, E> {
                limits::check_seconds("the time", v).map_err(E::custom)?;
                Ok(Timestamp::from_seconds(v))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Timestamp, E> {
                self.visit_f64(v as f64)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Timestamp, E> {
                self.visit_f64(v as f64)
            }
        }
        d.deserialize_any(V).map(Stamp)
    }
}

/// `hinge_offset`: 3 numbers.
pub(super) struct Offset(pub(super) [f64; 3]);

impl Value for Offset {
    type Out = [f64; 3];
    fn into_out(self) -> [f64; 3] {
        self.0
    }
}

impl<'de> Deserialize<'de> for Offset {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let Array(v) = Array::<Num>::deserialize(d)?;
        match v[..] {
            [Num(x), Num(y), Num(z)] => Ok(Offset([x, y, z])),
            _ => Err(de::Error::custom(format!(
                "must be 3 numbers [x, y, z], not {}",
                v.len()
            ))),
        }
    }
}
