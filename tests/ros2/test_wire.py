"""rmw_zenoh's keys, tokens, QoS strings and attachments, against golden values.

The golden strings are the examples of rmw_zenoh's design document (ros2/rmw_zenoh,
docs/design.md, "Topic" and "Graph Cache" sections: the ``listener`` node of the
talker/listener demo subscribing to ``/chatter``), and the QoS strings are checked
against zenoh-ros2-sdk's encoder, an implementation of the protocol that is not ours.
"""

from __future__ import annotations

import pytest

from twinfleet.ros2.wire import (
    ATTACHMENT_SIZE,
    LATCHED,
    SENSOR_DATA,
    Attachment,
    Durability,
    Endpoint,
    EntityKind,
    History,
    NodeId,
    Qos,
    Reliability,
    WireError,
    data_key,
    dds_type_name,
    endpoint_token,
    node_token,
    parse_token,
    ros_type_name,
)

pytestmark = pytest.mark.offline  # starts no fleet, opens no Zenoh session

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ZID = "aac3178e146ba6f1fc6e6a4085e77f21"
DESIGN_NODE = f"@ros2_lv/0/{ZID}/0/0/NN/%/%/listener"
DESIGN_SUB = (f"@ros2_lv/0/{ZID}/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/"
              f"{STRING_HASH}/::,10:,:,:,,")
DESIGN_KEY = f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"


def test_the_design_documents_examples_are_produced_exactly():
    node = NodeId(0, ZID, 0, "/", "listener")
    sub = Endpoint(node, 10, EntityKind.SUBSCRIPTION, "/chatter", "std_msgs/msg/String",
                   STRING_HASH)
    assert node_token(node) == DESIGN_NODE
    assert endpoint_token(sub) == DESIGN_SUB
    assert data_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH) == DESIGN_KEY
    assert sub.key == DESIGN_KEY
    assert parse_token(DESIGN_NODE) == node
    assert parse_token(DESIGN_SUB) == sub


def test_namespaces_and_topics_are_escaped_and_round_trip():
    node = NodeId(3, ZID, 7, "/fleet/r1", "robot")
    pub = Endpoint(node, 9, EntityKind.PUBLISHER, "/fleet/r1/scan", "sensor_msgs/msg/LaserScan",
                   "RIHS01_00", SENSOR_DATA)
    token = endpoint_token(pub)
    assert token.split("/")[6:10] == ["%", "%fleet%r1", "robot", "%fleet%r1%scan"]
    assert parse_token(token) == pub
    assert pub.key == "3/fleet/r1/scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_00"


@pytest.mark.parametrize("bad", ["@ros2_lv/0/z/0/0/NN/%/%", "@ros2_lv/0/z/0/0/XX/%/%/n",
                                 "@ros2_lv/0/z/0/0/NN/%//n", "0/chatter", "@other/0/z/0/0/NN/%/%/n"])
def test_malformed_tokens_are_refused(bad):
    with pytest.raises(WireError):
        parse_token(bad)


def test_empty_fields_are_refused_when_building():
    with pytest.raises(WireError):
        node_token(NodeId(0, ZID, 0, "/", ""))
    with pytest.raises(WireError):
        data_key(0, "/", "std_msgs/msg/String", STRING_HASH)


def test_qos_strings_equal_zenoh_ros2_sdks():
    from zenoh_ros2_sdk.qos import QosDurability, QosProfile, QosReliability

    assert Qos().encode() == QosProfile().encode() == "::,10:,:,:,,"
    assert LATCHED.encode() == QosProfile(durability=QosDurability.TRANSIENT_LOCAL,
                                          history_depth=1).encode() == ":1:,1:,:,:,,"
    assert SENSOR_DATA.encode() == QosProfile(reliability=QosReliability.BEST_EFFORT,
                                              history_depth=5).encode() == "2::,5:,:,:,,"
    keep_all = Qos(history=History.KEEP_ALL, depth=0)
    assert keep_all.encode() == "::2,0:,:,:,,"
    for qos in (Qos(), LATCHED, SENSOR_DATA, keep_all,
                Qos(Reliability.BEST_EFFORT, Durability.TRANSIENT_LOCAL, deadline=(1, 5))):
        assert Qos.decode(qos.encode()) == qos
    assert Qos.decode(Qos(deadline=(1, 5)).encode()).deadline == (1, 5)
    with pytest.raises(WireError):
        Qos.decode("::,10:,:,:")


def test_attachment_is_33_bytes_and_reads_as_the_sdk_reads_it():
    from zenoh_ros2_sdk.attachment import Attachment as SdkAttachment

    ours = Attachment(42, 1_700_000_000_123_456_789, bytes(range(16)))
    data = ours.encode()
    assert len(data) == ATTACHMENT_SIZE == 33
    theirs = SdkAttachment.from_bytes(data)
    assert (theirs.sequence_id, theirs.timestamp_ns, theirs.gid) == (42, ours.source_ns, ours.gid)
    assert Attachment.decode(SdkAttachment(7, 9, bytes(16)).to_bytes()) == Attachment(7, 9, bytes(16))
    for bad in (data[:-1], data[:16] + b"\x08" + data[17:]):
        with pytest.raises(WireError):
            Attachment.decode(bad)


def test_dds_type_names():
    assert dds_type_name("sensor_msgs/msg/LaserScan") == "sensor_msgs::msg::dds_::LaserScan_"
    assert ros_type_name("example_interfaces::srv::dds_::AddTwoInts_") == \
        "example_interfaces/srv/AddTwoInts"
    with pytest.raises(WireError):
        dds_type_name("LaserScan")
