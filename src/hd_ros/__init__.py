"""hd_ros: the ROS 2 plumbing of the stack, the layer right above ``hd_bag`` and below every estimator.

Modules (one concept each; rclpy is imported inside functions, so importing them is cheap):

* :mod:`hd_ros.topics`: topic names, message type names, the one table topic -> (type, QoS class),
  the fixed table of interface packages a type name may load a class from, ``ros2msg`` schema text;
* :mod:`hd_ros.qos`: the QoS profiles of the topic classes, ``offered_qos_profiles`` YAML;
* :mod:`hd_ros.context`: contexts and domains, real-time scheduling, Fast DDS publication mode, executors;
* :mod:`hd_ros.cdr`: fast CDR decoders of the live hot path (JointState, Temperature);
* :mod:`hd_ros.convert`: Float64MultiArray tables, JSON strings, stamps, taking a subscription's queue;
* :mod:`hd_ros.diagnostics`: DiagnosticStatus construction, callback containment;
* :mod:`hd_ros.managed`: the managed (lifecycle) node base of the four nodes and their parameter
  boilerplate (imports rclpy: import it only in node modules);
* :mod:`hd_ros.rtthread`: ``RtSubscription``, one subscription on its own node + executor thread,
  optionally ``SCHED_FIFO`` (any node's lowest-latency input);
* :mod:`hd_ros.replay`, :mod:`hd_ros.record`: the replay and record runtimes (they need no stack node).

This package namespace re-exports the names of the first six modules (``import hd_ros as ru``;
``ru.TOPIC_HEALTH``, ``ru.qos("latched")``, ``ru.pack_table(...)``): node shells use one prefix for the
plumbing. It imports nothing above ``hd_bag``.
"""

from hd_ros.cdr import (MAX_JOINTS, MAX_JOINTSTATE_BYTES, CdrError, decode_joint_state, decode_joint_states,  # noqa: F401
                        decode_temperature)
from hd_ros.context import (EXECUTOR, PUBLICATION_MODE_ENV, init_context, make_executor,  # noqa: F401
                            publication_mode, set_thread_realtime)
from hd_ros.convert import (MAX_JSON_BYTES, MAX_JSON_DEPTH, json_msg, ns_to_stamp, pack_table,  # noqa: F401
                            parse_json_msg, stamp_to_ns, take_all, unpack_table)
from hd_ros.diagnostics import contain_callbacks, diag_array, diag_status  # noqa: F401
from hd_ros.qos import SENSOR_DEPTH, mission_sub_qos, offered_qos_yaml, qos, topic_qos  # noqa: F401
from hd_ros.topics import (CONTRACT_TOPICS, MESSAGE_PACKAGES, STACK_TOPICS, TOPIC_COMMAND, TOPIC_DIAGNOSTICS,  # noqa: F401
                           TOPIC_FEATURES, TOPIC_GROUND_REPORT, TOPIC_HEALTH, TOPIC_JOINT_STATES, TOPIC_MISSION,
                           TOPIC_RESIDUALS, TOPIC_TEMPERATURE, TOPIC_TWIN_STATE, TOPIC_TWIN_UPDATE, TYPE_DIAG_ARRAY,
                           TYPE_F64_ARRAY, TYPE_JOINT_STATE, TYPE_STRING, TYPE_TEMPERATURE, message_class,
                           message_definition)
