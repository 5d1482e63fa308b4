"""The composition file as typed models: threads, activities, streams and coordination.

Every named thing is a mapping key, never a list item, so a JSON Patch path such as
`/activities/haptic/params/kp` stays valid when other entries come and go. Each model
forbids unknown keys: a typo is an error, not a silently ignored setting.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator
from pydantic_core import PydanticCustomError

from hapticop.composition.ros2streams import Ros2Stream, Ros2System
from hapticop.composition.units import Duration, Offset
from hapticop.network.link import LinkParams

VERSION = 1

Name = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]*$", description="lower_snake_case name")]
PlaceName = Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$")]
PortRef = Annotated[
    str,
    Field(pattern=r"^[a-z][a-z0-9_]*\.[a-z][a-z0-9_]*$", description="'activity.port'"),
]
FlagName = Annotated[
    str,
    Field(pattern=r"^[a-z][a-z0-9_]*(\.[a-z0-9_]+)+$", description="dotted flag name, e.g. 'falcon.lcsm.running'"),
]
Weight = Annotated[int, Field(ge=1, le=1_000_000)]
StartPolicy = Literal["auto", "on_request"]
LogLevel = Literal["always", "error", "warning", "info", "debug"]
START_DOC = (
    "'auto': the LCSM goes on to running as soon as it is configured; 'on_request': it waits in "
    "capability configuration until a flag map sets its 'lcsm.request_running' flag"
)


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)


class Thread(Strict):
    """A time-triggered thread: each cycle it runs its selected schedule, then sleeps."""

    period: Duration = Field(description="cycle time or rate: '1ms', '15Hz', '66.667ms'")
    priority: int | None = Field(
        None, description="SCHED_FIFO priority 1-98; omit for normal scheduling",
        json_schema_extra={"minimum": 1, "maximum": 98},
    )
    cpus: list[Annotated[int, Field(ge=0, le=4095)]] | None = Field(
        None, description="CPU affinity: the cores this thread may run on"
    )
    deploy: Literal["main", "thread", "process"] = Field(
        "thread",
        description="'main': the process's main thread (runs the mediator); "
        "'thread': a thread of the main process; 'process': its own process",
    )
    process: Name | None = Field(
        None, description="with 'deploy: process', threads naming the same process share it (a fieldbus and "
        "the watchdog that acts on its master); default: a process of the thread's own",
    )
    schedules: dict[Annotated[int, Field(ge=0, le=255)], list[Name]] = Field(
        description="activity-scheduler sets by ID; ID 0 is selected at start"
    )
    phase: Offset | Literal["auto"] = Field(
        0,
        description="offset of the deadlines within the period, e.g. '500us' to run after another loop's "
        "output is ready; 'auto' staggers the threads of equal period evenly, highest priority first. "
        "Default 0: loops of equal period wake together (docs/realtime.md, the real-time bench)",
    )
    busy_wait: Offset = Field(
        0, description="spin this long before each deadline instead of sleeping through it: "
        "lower wake-up latency for a core's worth of CPU, e.g. '50us'; 0 sleeps all the way",
    )
    wake: Literal["deadline", "data"] = Field(
        "deadline", description="'deadline': cycle at the period's deadlines only; 'data': also cycle as soon "
        "as a device socket of its activities has data (a LIDAR's telegram is parsed when its last byte "
        "arrives, not up to a period later). Real time only; the virtual clock cycles at the deadlines",
    )
    start: StartPolicy = Field("auto", description=START_DOC)
    log: LogLevel = Field("info", description="the most detailed level written to this thread's log")
    host: Name | None = Field(None, description="with 'hosts:', the host this thread (and its process) runs on")
    doc: str = ""

    @field_validator("process")
    @classmethod
    def _process_needs_deploy(cls, value: str | None, info: ValidationInfo) -> str | None:
        if value is not None and info.data.get("deploy") != "process":
            raise PydanticCustomError("process_without_deploy", "'process' names a shared process: it needs "
                                      "'deploy: process'")
        return value

    def process_name(self, thread: str) -> str | None:
        """The process this thread runs in, for 'deploy: process' threads (None: the main process)."""
        return (self.process or thread) if self.deploy == "process" else None

    @field_validator("phase", "busy_wait")
    @classmethod
    def _within_period(cls, value: int | str, info: ValidationInfo) -> int | str:
        period = info.data.get("period")
        if value != "auto" and period is not None and value >= period:
            raise PydanticCustomError("longer_than_period", "{field} must be shorter than the period ({period} ns)",
                                      {"field": info.field_name, "period": period})
        return value

    @field_validator("priority")
    @classmethod
    def _in_range(cls, value: int | None) -> int | None:
        """One range, 1 to 98, and one message for anything outside it (99 included, with why)."""
        if value is not None and not 1 <= value <= 98:
            raise PydanticCustomError(
                "priority_range",
                "priority {value} is outside 1 to 98: SCHED_FIFO runs 1 (lowest) to 99, and 99 is left to the "
                "kernel's own real-time threads, which a thread at 99 would never yield to (thesis 2.3.2)",
                {"value": value},
            )
        return value

    @field_validator("cpus")
    @classmethod
    def _unique_cpus(cls, value: list[int] | None) -> list[int] | None:
        if value is not None and len(set(value)) != len(value):
            raise PydanticCustomError("cpus_repeated", "a CPU is listed twice in {cpus}", {"cpus": value})
        if value is not None and not value:
            raise PydanticCustomError("cpus_empty", "an empty CPU set leaves the thread nowhere to run")
        return value


class Activity(Strict):
    """An instance of a block with its parameters."""

    block: str = Field(
        pattern=r"^([a-z][a-z0-9_]*|[A-Za-z_][\w.]*:[A-Za-z_]\w*)$",
        description="a built-in block name, or 'package.module:ClassName'",
    )
    params: dict[str, Any] = Field(default_factory=dict, description="checked against the block's parameter model")
    start: StartPolicy = Field("auto", description=START_DOC)
    log: LogLevel = Field("info", description="the most detailed level written to this activity's log")
    doc: str = ""


class LatestPolicy(Strict):
    """Readers see the most recent sample (a seqlock slot across threads)."""

    kind: Literal["latest"] = "latest"
    sync: Literal["lock_free", "none"] = Field(
        "lock_free", description="'none' is a plain slot, only valid within one thread"
    )


class QueuePolicy(Strict):
    """Readers see every sample in order, up to `capacity` (an SPSC ring per reader)."""

    kind: Literal["queue"] = "queue"
    capacity: int = Field(8, ge=1, le=65536)
    overflow: Literal["drop_oldest", "drop_newest"] = "drop_oldest"
    sync: Literal["lock_free", "none"] = "lock_free"


StreamPolicy = Annotated[LatestPolicy | QueuePolicy, Field(discriminator="kind")]


class NetworkQoS(Strict):
    """How a stream whose writer and readers are on different hosts crosses the network (docs/teleop.md).

    Only the hosts' bridges touch the network: the real-time threads read and write the shared
    region as they do for any stream, so nothing here can make them wait."""

    priority: Literal["real_time", "interactive", "data", "background"] = Field(
        "data", description="Zenoh priority: 'real_time' for setpoints, 'data' for scans")
    keep: Literal["newest", "queue"] = Field(
        "newest", description="'newest': a late sample replaces an older one and an older one is dropped (state); "
        "'queue': every sample in order, up to 'depth' (events)")
    depth: Annotated[int, Field(ge=1, le=65536)] | None = Field(
        None, description="with keep 'queue': samples held at most; required, a queue without a bound grows "
        "without one while the reader lags")
    reliability: Literal["best_effort", "reliable"] = Field(
        "best_effort", description="'reliable' retransmits (TCP); 'best_effort' never waits for a lost sample")
    congestion: Literal["drop", "block"] = Field(
        "drop", description="a full link: 'drop' the sample, or 'block' the bridge until it leaves")
    deadline: Duration | None = Field(
        None, description="a sample older than this when read (send time mapped to the reader's clock) is stale; "
        "required")
    stale: Literal["zero", "hold"] | None = Field(
        None, description="what the reading side does with a stale sample: 'zero' treats it as no sample "
        "(a setpoint ramps the wheels down), 'hold' keeps using the last one (a scan); required")
    doc: str = ""


class Stream(Strict):
    """One writer port to one or more reader ports, with an explicit connection policy."""

    writer: PortRef | None = Field(None, alias="from", description="the writing port, 'activity.port' (none: "
                                   "with 'ros2:', subscribed from ROS 2)")
    readers: list[PortRef] = Field(
        default_factory=list, alias="to", description="the reading ports; none: a stream only watched (recorded, "
        "plotted, in the live view), as a network bridge's link figures are")
    policy: StreamPolicy = Field(default_factory=LatestPolicy)
    max_age: Duration | None = Field(None, description="older samples count as missing")
    network: NetworkQoS | None = Field(
        None, description="with 'hosts:', how the stream crosses the network when its writer and readers are on "
        "different hosts")
    ros2: Ros2Stream | None = Field(None, description="a ROS 2 topic: published with no 'to', subscribed with no "
                                    "'from' (docs/ros2.md)")
    doc: str = ""

    @model_validator(mode="after")
    def _written(self) -> Stream:
        if self.writer is None:  # the loader gives a ROS 2 subscription its writer (composition/ros2streams.py)
            raise PydanticCustomError("stream_writer", "'from' is missing: a stream has one writer port (with "
                                      "'ros2:' and the system's 'ros2:' node, none: subscribed from ROS 2)")
        return self

    @model_validator(mode="before")
    @classmethod
    def _shorthands(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        data = dict(data)
        if isinstance(data.get("to"), str):
            data["to"] = [data["to"]]
        if isinstance(data.get("policy"), str):
            data["policy"] = {"kind": data["policy"]}
        return data


    @field_validator("writer", mode="before")
    @classmethod
    def _one_writer(cls, value: Any) -> Any:
        if isinstance(value, list):
            raise PydanticCustomError(
                "stream_one_writer",
                "a stream has exactly one writer port, got {count}; make one stream per writer",
                {"count": len(value)},
            )
        return value


class Place(Strict):
    doc: str = ""


class Transition(Strict):
    """Fires when every input place holds its arc weight in tokens and every `unless` place is empty."""

    inputs: dict[PlaceName, Weight] = Field(alias="in", description="input places and arc weights")
    outputs: dict[PlaceName, Weight] = Field(default_factory=dict, alias="out")
    inhibitors: list[PlaceName] = Field(
        default_factory=list, alias="unless",
        description="places that must be empty for it to fire (inhibitor arcs): a place tracking a flag makes "
                    "the net react to that flag being false")
    doc: str = ""

    @field_validator("inputs", "outputs", mode="before")
    @classmethod
    def _list_means_weight_one(cls, value: Any) -> Any:
        if isinstance(value, list):
            return {name: 1 for name in value} if all(isinstance(n, str) for n in value) else value
        return value


class PetriNet(Strict):
    """A place/transition net, fired to a steady state each coordination step."""

    places: dict[PlaceName, Place | None]
    transitions: dict[PlaceName, Transition]
    marking: dict[PlaceName, Annotated[int, Field(ge=0, le=1_000_000)]] = Field(
        default_factory=dict, description="initial tokens per place (others start empty)"
    )
    terminal: list[PlaceName] = Field(
        default_factory=list,
        description="places whose marking ends the net's work: a dead marking is expected there",
    )
    doc: str = ""


class FlagMap(Strict):
    """Binds flags to the places of one net (the four kinds of docs/coordination.md)."""

    net: Name
    converting_sources: dict[FlagName, PlaceName] = Field(
        default_factory=dict, description="flag true: clear it and add a token (an event in)"
    )
    tracking_sources: dict[FlagName, PlaceName] = Field(
        default_factory=dict, description="the place holds one token while the flag is true (a level in)"
    )
    converting_sinks: dict[FlagName, PlaceName] = Field(
        default_factory=dict, description="a token in the place: remove it and set the flag (an event out)"
    )
    tracking_sinks: dict[FlagName, PlaceName] = Field(
        default_factory=dict, description="the flag is true while the place holds a token (a level out)"
    )
    doc: str = ""


class StandardCoordination(Strict):
    """The coordination most applications share, declared once and written out as ordinary nets and flag
    maps before validation (`hapticop/composition/standard.py`, docs/coordination.md section 8).

    It starts the threads that wait for a request, selects their schedules, waits until the named
    activities run (then the application operates), and on Ctrl+C or an end event cleans the named
    activities stage by stage, then the threads, then sets `system.exit`."""

    threads: list[Name] | None = Field(
        None, description="threads to start on request and clean at the end; default: every 'start: on_request' thread"
    )
    select: dict[Name, Annotated[int, Field(ge=0, le=255)]] = Field(
        default_factory=dict, description="the schedule each thread changes to once its thread runs; default: "
        "schedule 1 of every thread that has one. 0 keeps a thread on schedule 0 on purpose",
    )
    wait_for: list[Name] = Field(
        default_factory=list, description="activities whose 'lcsm.running' must all hold before the application "
        "operates (place OPERATING)",
    )
    ends: dict[FlagName, PlaceName] = Field(
        default_factory=dict, description="events that end the operating application as Ctrl+C does "
        "('system.shutdown_requested', place SHUTDOWN, always does), each with its place",
    )
    clean: dict[Name, list[Name]] = Field(
        default_factory=dict, description="cleaning stages in order, each a name and its activities; a stage "
        "starts when the one before is done. Activities left out are cleaned by the runtime after 'system.exit'",
    )
    sources: dict[FlagName, PlaceName] = Field(
        default_factory=dict, description="level flags the mediator net mirrors in places of its own (tracking "
        "sources): 'ethercat_watchdog.slave_fault: WHEEL_FAULT'",
    )
    sinks: dict[FlagName, PlaceName] = Field(
        default_factory=dict, description="flags that mirror a place of the mediator net (tracking sinks): "
        "'haptic.resources_ready: OPERATING'",
    )
    doc: str = ""


class Coordination(Strict):
    """Petri nets and the flag maps through which the mediator drives every LCSM."""

    standard: StandardCoordination | None = Field(
        None, description="the standard start, schedule selection and ordered cleaning, written out as the nets "
        "'mediator', 'thread_lcsm' and 'thread_scheduler' (`hapticop expand` prints them)",
    )

    flags: dict[Name, str | None] = Field(
        default_factory=dict, description="coupling flags between nets, referenced as 'flags.NAME'"
    )
    nets: dict[Name, PetriNet] = Field(default_factory=dict)
    flag_maps: dict[Name, FlagMap] = Field(default_factory=dict)


class ScriptedPatch(Strict):
    """A live patch the mediator applies by itself, this long after the start (scripted runs)."""

    at: Duration = Field(description="time after the start, e.g. '10s'")
    patch: list[dict[str, Any]] | dict[str, Any] = Field(
        description="a JSON Patch (a list of operations) or a merge patch (a mapping)"
    )
    doc: str = ""


class Mode(Strict):
    """Parameter values that hold while a flag is true: "parked" with a stiffer centring, say.

    Only parameters a block retunes while running may change with a mode, so entering and
    leaving one never takes an activity out of running."""

    when: FlagName = Field(description="the flag that selects the mode: it holds while the flag is true")
    params: dict[Name, dict[str, Any]] = Field(
        description="per activity, parameter values merged over its own while the mode holds")
    doc: str = ""


MAX_LATENCIES = 5
"""End-to-end latencies a composition may track (each sample carries one origin stamp per latency)."""


class Latency(Strict):
    """An end-to-end latency measured while running: from a sample leaving an output port to
    the first step of the reading activity that consumes something derived from it."""

    source: PortRef = Field(alias="from", description="the output port where the measured path starts")
    sink: PortRef = Field(alias="to", description="the input port where it ends")
    doc: str = ""


class Record(Strict):
    """Every sample of the chosen streams kept in one MCAP file per run, by a recorder process
    outside the real-time loops (`hapticop compose --record` turns it on for any file)."""

    streams: Literal["all"] | list[Name] = Field("all", description="the streams to record, or 'all'")
    decimate: dict[Name, Annotated[int, Field(ge=1, le=1_000_000)]] = Field(
        default_factory=dict, description="record only every Nth sample of these streams, e.g. {scan_ranges: 2}")
    depth: Duration = Field(
        3_000_000_000, description="how long the recorder may be descheduled before samples are lost: each "
        "recorded stream gets a ring of this many seconds of its samples, written by the loop, read by the recorder",
        json_schema_extra={"default": "3s"})
    doc: str = ""


class Host(Strict):
    """A machine the composition runs on: its own runtime, and a bridge that reaches the others
    over Zenoh in peer mode at these endpoints (no multicast scouting)."""

    endpoints: list[Annotated[str, Field(pattern=r"^(tcp|udp|quic|tls)/[^/]+:[0-9]+$")]] = Field(
        min_length=1, description="where this host's bridge listens, e.g. 'tls/10.0.0.1:7447' (with keys, 'tls/' "
        "or 'quic/'); the other hosts connect to them")
    emulate: LinkParams | None = Field(
        None, description="make what this host receives worse on purpose (delay, jitter, loss: a seeded emulated "
        "link in its bridge), to test or measure a good network as a bad one")
    bridge_period: Duration = Field(
        "1ms", validate_default=True, description="how often this host's bridge moves samples between the shared "
        "region and the network: a crossing waits up to a period on either side, so a shorter one takes that much "
        "off a sample's age at the price of the bridge's CPU ('500us' halves both)")
    transport: Literal["prioritised", "low_latency"] = Field(
        "prioritised", description="how Zenoh carries this host's link: 'prioritised' queues each message by its "
        "stream's priority, so a setpoint overtakes a queued scan; 'low_latency' writes each message straight on "
        "the link (a shorter round trip) with no queue to overtake in, the bridge sending its streams in priority "
        "order; every host must say the same")
    bridge_cpus: list[Annotated[int, Field(ge=0, le=4095)]] | None = Field(
        None, min_length=1, description="the cores this host's bridge process (and Zenoh's threads in it) may run "
        "on: keep the network off the real-time loops' cores")
    on_link_lost: list[PlaceName] = Field(
        default_factory=list, description="places of the other hosts' mediators this host holds while the link is "
        "lost, as if they had a token (a robot out of reach is treated as a held one: 'WHEEL_FAULT'); they follow "
        "the other host again once it is heard")
    doc: str = ""


class Security(Strict):
    """How the hosts' bridges prove who they are and hide what they carry (docs/security.md): mutual TLS
    with a CA of the system's own, and on each host rules that let each other host put only the streams it
    writes and read only what it is sent."""

    keys: str | None = Field(
        None, description="the directory of the link's keys, relative to the file that names it: 'ca.pem', and "
        "'HOST.pem' and 'HOST.key' for each host (`hapticop hosts keys FILE` makes them)")
    insecure: bool = Field(
        False, description="no keys: plain links that anyone who reaches a host may join, read and drive; "
        "for a closed test network only (validate warns, the run says so first)")
    doc: str = ""


class Composition(Strict):
    """A whole hapticop system: what runs, where, how it is wired and coordinated."""

    version: Literal[1] = Field(description="composition format version")
    name: Name | None = None
    doc: str = ""
    hosts: dict[Name, Host] = Field(
        default_factory=dict, description="the machines the composition runs on; each thread names its 'host:'")
    security: Security = Field(
        default_factory=Security, description="with 'hosts:', the link's keys (or, on a closed test network, "
        "'insecure: true')")
    threads: dict[Name, Thread] = Field(min_length=1)
    activities: dict[Name, Activity] = Field(min_length=1)
    streams: dict[Name, Stream] = Field(default_factory=dict)
    coordination: Coordination = Field(default_factory=Coordination)
    patches: dict[Name, ScriptedPatch] = Field(
        default_factory=dict, description="patches applied while running, at given times"
    )
    modes: dict[Name, Mode] = Field(
        default_factory=dict, description="parameter values that hold while a flag is true; when several hold, "
        "a later mode's values win")
    latencies: dict[Name, Latency] = Field(
        default_factory=dict, max_length=MAX_LATENCIES,
        description="end-to-end latencies to measure and report, e.g. handle displacement to wheel command",
    )
    ros2: Ros2System | None = Field(None, description="the ROS 2 node that carries the streams with 'ros2:'")
    duration: Duration | None = Field(None, description="the system stops by itself after this long, e.g. '60s'")
    record: Record | None = Field(None, description="record streams to an MCAP file while running")
    cpu_dma_latency: int | None = Field(
        0, ge=0, le=1_000_000, description="while real-time threads run, hold /dev/cpu_dma_latency at this many "
        "microseconds so deep CPU idle states do not delay wake-ups; null leaves power management alone",
    )

    @field_validator("version", mode="before")
    @classmethod
    def _known_version(cls, value: Any) -> Any:
        if value != VERSION:
            raise PydanticCustomError(
                "version",
                "composition version {value} is not supported; this hapticop reads version {known}",
                {"value": repr(value), "known": VERSION},
            )
        return value


# Where the named entries live; used to drop a broken entry and keep checking the rest.
COLLECTIONS: tuple[tuple[str, ...], ...] = (
    ("hosts",),
    ("threads",),
    ("activities",),
    ("streams",),
    ("coordination", "flags"),
    ("coordination", "nets"),
    ("coordination", "flag_maps"),
    ("patches",),
    ("latencies",),
)
# The room a running system keeps for what live patches add: its shared region is sized at start.
SPARE_ACTIVITIES = 16
SPARE_FLAGS = 1024
ARENA_BYTES = 1 << 20  # stream buffers added live

RESERVED_NAMES = frozenset({"threads", "system", "flags"})
