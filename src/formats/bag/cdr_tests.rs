use super::*;

fn header(sec: i32, nanosec: u32, frame: &str) -> Header {
    Header {
        stamp: Time { sec, nanosec },
        frame_id: frame.into(),
    }
}

#[test]
fn string_message_matches_hand_computed_bytes() {
    let bytes = StringMsg { data: "ok".into() }.to_cdr();
    // Header 00 01 00 00, length 3 (with the NUL), 'o' 'k' NUL.
    assert_eq!(bytes, vec![0, 1, 0, 0, 3, 0, 0, 0, b'o', b'k', 0]);
    assert_eq!(StringMsg::from_cdr(&bytes).unwrap().data, "ok");
}

#[test]
fn laser_scan_matches_hand_computed_bytes() {
    let scan = LaserScan {
        header: header(1000, 5, "l"),
        angle_min: 0.5,
        angle_increment: 1.0,
        range_max: 2.0,
        ranges: vec![1.5],
        ..LaserScan::default()
    };
    let mut want: Vec<u8> = vec![0, 1, 0, 0];
    want.extend(1000u32.to_le_bytes());
    want.extend(5u32.to_le_bytes());
    want.extend([2, 0, 0, 0, b'l', 0, 0, 0]); // "l" + NUL, padded to 4 for the next f32
    for v in [0.5f32, 0.0, 1.0, 0.0, 0.0, 0.0, 2.0] {
        want.extend(v.to_le_bytes());
    }
    want.extend(1u32.to_le_bytes());
    want.extend(1.5f32.to_le_bytes());
    want.extend(0u32.to_le_bytes());
    assert_eq!(scan.to_cdr(), want);
    assert_eq!(LaserScan::from_cdr(&want).unwrap(), scan);
}

#[test]
fn joint_state_aligns_doubles_to_eight() {
    let js = JointState {
        header: header(1, 2, ""),
        name: vec!["hinge".into()],
        position: vec![0.25],
        ..JointState::default()
    };
    let b = js.to_cdr();
    // sec 0..4, nanosec 4..8, frame_id length 8..12 and its NUL at 12; name count 16..20,
    // "hinge" length 20..24 and bytes 24..30; position count 32..36; the double aligned to 40.
    assert_eq!(&b[4 + 32..4 + 36], &1u32.to_le_bytes());
    assert_eq!(&b[4 + 40..4 + 48], &0.25f64.to_le_bytes());
    assert_eq!(JointState::from_cdr(&b).unwrap(), js);
}

#[test]
fn every_type_round_trips() {
    let mut odom = Odometry {
        header: header(7, 8, "odom"),
        child_frame_id: "base_link".into(),
        ..Odometry::default()
    };
    odom.pose.position = [1.0, 2.0, 3.0];
    odom.pose_covariance[35] = 0.5;
    odom.twist[5] = 0.1;
    assert_eq!(Odometry::from_cdr(&odom.to_cdr()).unwrap(), odom);
    let ps = PoseStamped {
        header: header(9, 10, "world"),
        pose: Pose {
            position: [4.0, 5.0, 6.0],
            orientation: quaternion_from_rpy(0.1, 0.2, 0.3),
        },
    };
    assert_eq!(PoseStamped::from_cdr(&ps.to_cdr()).unwrap(), ps);
    let imu = Imu {
        header: header(1, 1, "laser_level"),
        orientation: [0.0, 0.1, 0.0, 0.99],
        orientation_covariance: [1.0; 9],
        angular_velocity_covariance: [-1.0; 9],
        ..Imu::default()
    };
    assert_eq!(Imu::from_cdr(&imu.to_cdr()).unwrap(), imu);
}

#[test]
fn big_endian_input_decodes() {
    let mut b = vec![0, 0, 0, 0];
    b.extend(3u32.to_be_bytes());
    b.extend(b"hi\0");
    assert_eq!(StringMsg::from_cdr(&b).unwrap().data, "hi");
}

#[test]
fn truncated_and_lying_messages_are_errors() {
    let b = LaserScan {
        ranges: vec![1.0; 10],
        ..LaserScan::default()
    }
    .to_cdr();
    for cut in [0, 3, 10, 40, b.len() - 1] {
        assert!(LaserScan::from_cdr(&b[..cut]).is_err(), "cut at {cut}");
    }
    let mut lying = b.clone();
    // The ranges count: header (13 bytes with the empty frame id, padded to 16), 7 floats.
    lying[4 + 44..4 + 48].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = LaserScan::from_cdr(&lying).unwrap_err();
    assert!(e.0.contains("ranges"), "{e}");
}
