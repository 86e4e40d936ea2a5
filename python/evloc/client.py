"""A typed client of the evloc-localizer service (docs/api.md): sessions as context managers,
events sent PACKED (encoded with NumPy), poses back as NumPy arrays, statuses as evloc.Status, and
reconnection as evloc-replay does it (a new session at the last pose on another try, full-jitter
backoff bounded in attempts and time, the server's pushback honoured; docs/deploy.md).

    with evloc.Client("127.0.0.1:50051", token="...") as client:
        with client.session("room", camera, initial_pose=pose, initial_t_ns=t0) as session:
            session.send(events)
            session.close()                 # no more events: the server ends the session
            for update in session.poses():
                print(update.t_ns, update.status, update.pose)

The gRPC stubs (evloc.localizer_pb2, evloc.localizer_pb2_grpc) are generated from proto/ when
the package is built."""

import collections
import math
import queue
import random
import threading
import time

import grpc
import numpy as np

from evloc.status import Status

try:
    from evloc import localizer_pb2, localizer_pb2_grpc, map_pb2
except ImportError as _missing:  # a source checkout: the stubs are made by setup.py
    localizer_pb2 = localizer_pb2_grpc = map_pb2 = None
    _STUBS_ERROR = _missing
else:
    _STUBS_ERROR = None

# PACKED: 8 bytes per event, little-endian uint32 (t - time_base | ON << 31), uint16 x, uint16 y.
PACKED_DTYPE = np.dtype([("word", "<u4"), ("x", "<u2"), ("y", "<u2")])
MAX_PACKED_OFFSET_NS = 0x7FFFFFFF
# Status codes after which a session is resumed elsewhere (evloc-replay's IsTransient).
TRANSIENT_CODES = frozenset({grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.CANCELLED,
                             grpc.StatusCode.ABORTED, grpc.StatusCode.UNKNOWN,
                             grpc.StatusCode.RESOURCE_EXHAUSTED})
_CAMERA_MODELS = {"pinhole": 1, "radtan": 2, "equidistant": 3}


def _fill_camera(camera, message):
    """Fills an evloc.map_format.Camera message from a camera dict (evloc.Dataset.camera)."""
    model = camera.get("model", "pinhole")
    if model not in _CAMERA_MODELS:
        raise ValueError(f"camera model {model!r} is not one of {sorted(_CAMERA_MODELS)}")
    message.model = _CAMERA_MODELS[model]
    for key in ("width", "height", "fx", "fy", "cx", "cy"):
        setattr(message, key, camera[key])
    message.distortion.extend(camera.get("distortion", []))


def _pose_of(rigid):
    """7 values tx ty tz qx qy qz qw of an evloc.map_format.Rigid3 message."""
    return np.array([rigid.translation.x, rigid.translation.y, rigid.translation.z,
                     rigid.rotation.x, rigid.rotation.y, rigid.rotation.z, rigid.rotation.w])


def _stubs():
    if _STUBS_ERROR is not None:
        raise ImportError("evloc: the gRPC stubs are missing: install the package "
                          f"(pip install --no-build-isolation ./python, docs/python.md): "
                          f"{_STUBS_ERROR}")
    return localizer_pb2, localizer_pb2_grpc


class ServiceError(Exception):
    """A call failed: `code` (grpc.StatusCode), `details` (the server's message)."""

    def __init__(self, what, code, details):
        super().__init__(f"{what}: {code.name if code else 'no status'}: {details}")
        self.code = code
        self.details = details


def thinning_stride(events, span_ns, rate):
    """The stride k of the events kept (every k-th) so that `events` over `span_ns` stay within
    `rate` events per second (evloc-replay's ThinningStride): 1 when they do, when rate is 0 or the
    span is not positive."""
    if rate <= 0 or span_ns <= 0 or events <= 0:
        return 1
    allowed = rate * span_ns * 1e-9
    if events <= allowed:
        return 1
    if allowed < 1.0:
        return int(events)
    return int(math.ceil(events / allowed))


def encode_packed(t_ns, x, y, p, time_base_ns):
    """PACKED bytes of events relative to time_base_ns (docs/api.md). Raises ValueError when an
    event lies before the base or more than 2^31 - 1 ns after it."""
    offsets = np.asarray(t_ns, dtype=np.int64) - np.int64(time_base_ns)
    if len(offsets) and (offsets.min() < 0 or offsets.max() > MAX_PACKED_OFFSET_NS):
        raise ValueError("encode_packed: events must lie within 0 .. 2^31-1 ns of the time base")
    records = np.empty(len(offsets), dtype=PACKED_DTYPE)
    records["word"] = offsets.astype(np.uint32) | (np.asarray(p) > 0).astype(np.uint32) << 31
    records["x"] = x
    records["y"] = y
    return records.tobytes()


class Pose:
    """One pose update: t_ns, status (Status), pose (7,) `tx ty tz qx qy qz qw` world_from_cam
    or None while searching, covariance (6, 6) or None, quality (dict), step_ms, latency_us, and
    session (the 0-based index of the session it came from: > 0 after a reconnect)."""

    __slots__ = ("t_ns", "status", "pose", "covariance", "quality", "step_ms", "latency_us",
                 "session")

    def __init__(self, message, session):
        api, _ = _stubs()
        self.t_ns = message.t_ns
        self.status = Status[api.TrackingStatus.Name(message.status)]
        if message.HasField("world_from_cam"):
            self.pose = _pose_of(message.world_from_cam)
        else:
            self.pose = None
        self.covariance = (np.array(message.covariance).reshape(6, 6)
                           if len(message.covariance) == 36 else None)
        q = message.quality
        self.quality = {"on_edge_fraction": q.on_edge_fraction, "mean_residual": q.mean_residual,
                        "points_used": q.points_used, "points_selected": q.points_selected,
                        "iterations": q.iterations, "recovery_attempts": q.recovery_attempts}
        self.step_ms = message.step_ms
        self.latency_us = message.latency_us
        self.session = session

    def matrix(self):
        """The 4x4 world_from_cam, or None."""
        if self.pose is None:
            return None
        from evloc.trajectory import poses_to_matrices  # pylint: disable=import-outside-toplevel
        return poses_to_matrices(self.pose)[0]

    def __repr__(self):
        where = "no pose" if self.pose is None else "t=" + np.array2string(self.pose[:3],
                                                                           precision=4)
        return f"Pose({self.t_ns} ns, {self.status.name}, {where})"


class MapDescription:
    """A map the server offers: name, version, num_points, num_keyframes, bounding box
    (bounding_box_min, bounding_box_max as (3,) arrays), content_crc32c, file_bytes."""

    def __init__(self, message):
        self.name = message.name
        self.version = message.version
        self.num_points = message.num_points
        self.num_keyframes = message.num_keyframes
        self.bounding_box_min = np.array([message.bounding_box_min.x, message.bounding_box_min.y,
                                          message.bounding_box_min.z])
        self.bounding_box_max = np.array([message.bounding_box_max.x, message.bounding_box_max.y,
                                          message.bounding_box_max.z])
        self.content_crc32c = message.content_crc32c
        self.file_bytes = message.file_bytes

    def __repr__(self):
        return f"MapDescription({self.name!r} {self.version!r}, {self.num_points} points)"


class SessionEnd:
    """The server's totals of a session (SessionEnd): packets, events, poses, lost_poses,
    latency_p50_us, latency_p99_us, duration_s, ..."""

    def __init__(self, message):
        for field in message.DESCRIPTOR.fields:
            setattr(self, field.name, getattr(message, field.name))

    def __repr__(self):
        return f"SessionEnd({self.poses} poses, {self.lost_poses} LOST, {self.events} events)"


class LocateResult:
    """The answer of Locate (docs/relocalization.md): found, status ("FOUND" / "NOT_FOUND"), pose
    (7,) world_from_cam or None, covariance (6, 6) or None, inliers, keyframe, score, reason,
    map_version, locate_ms."""

    def __init__(self, message):
        api, _ = _stubs()
        self.status = api.LocateStatus.Name(message.status)
        self.found = message.status == api.FOUND
        self.pose = _pose_of(message.world_from_cam) if self.found else None
        self.covariance = (np.array(message.covariance).reshape(6, 6)
                           if self.found and len(message.covariance) == 36 else None)
        self.inliers = message.inliers
        self.keyframe = message.keyframe
        self.score = message.score
        self.reason = message.reason
        self.map_version = message.map.version
        self.locate_ms = message.locate_ms

    def __repr__(self):
        return f"LocateResult({self.status}, {self.inliers} inliers, {self.reason!r})"


class Client:
    """A connection to evloc-localizer. `tls`: None/False for plaintext (loopback only, as the
    server allows), True for TLS with the system's roots, or a dict with any of `ca`, `cert`,
    `key` (file paths; cert and key for mutual TLS). `token` or `token_file`: the bearer token
    (`authorization: Bearer TOKEN`)."""

    def __init__(self, address, token=None, tls=None, token_file=None, timeout_s=10.0,
                 reconnect_backoff_ms=100, reconnect_backoff_max_ms=2000):
        self.address = address
        # The channel's own reconnect backoff, as evloc-replay sets it (not the minimum: gRPC
        # also takes that as the shortest connect timeout).
        channel_options = [("grpc.initial_reconnect_backoff_ms", int(reconnect_backoff_ms)),
                           ("grpc.max_reconnect_backoff_ms", int(reconnect_backoff_max_ms)),
                           ("grpc.max_receive_message_length", 64 << 20)]
        if token_file is not None:
            with open(token_file, encoding="utf-8") as handle:
                token = handle.read().strip()
            if not token:
                raise ValueError(f"evloc.Client: the token file {token_file} is empty")
        self._metadata = (("authorization", "Bearer " + token),) if token else ()
        self.timeout_s = timeout_s
        if not tls:
            self._channel = grpc.insecure_channel(address, options=channel_options)
        else:
            files = {} if tls is True else dict(tls)
            unknown = set(files) - {"ca", "cert", "key"}
            if unknown:
                raise ValueError(f"evloc.Client: unknown tls keys {sorted(unknown)} "
                                 "(expected ca, cert, key)")

            def read(key):
                if key not in files:
                    return None
                with open(files[key], "rb") as handle:
                    return handle.read()

            credentials = grpc.ssl_channel_credentials(read("ca"), read("key"), read("cert"))
            self._channel = grpc.secure_channel(address, credentials, options=channel_options)
        _, api_grpc = _stubs()
        self._stub = api_grpc.LocalizerStub(self._channel)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Closes the channel."""
        self._channel.close()

    def list_maps(self):
        """The maps this client may use, as MapDescription."""
        api, _ = _stubs()
        try:
            response = self._stub.ListMaps(api.ListMapsRequest(), metadata=self._metadata,
                                           timeout=self.timeout_s)
        except grpc.RpcError as error:
            raise ServiceError("ListMaps", error.code(), error.details()) from None
        return [MapDescription(m) for m in response.maps]

    def locate(self, map_name, camera, image, timeout_s=30.0):
        """Locates one image in a map with relocalization data (the Locate RPC): `image` is the
        bytes of a PNG or JPEG file, or a 2-D uint8 array (grey). Returns a LocateResult; raises
        ServiceError when the call fails."""
        api, _ = _stubs()
        request = api.LocateRequest(map_name=map_name)
        _fill_camera(dict(camera), request.camera)
        if isinstance(image, (bytes, bytearray)):
            request.encoded = bytes(image)
        else:
            gray = np.ascontiguousarray(image, dtype=np.uint8)
            if gray.ndim != 2:
                raise ValueError("locate: image must be encoded bytes or a 2-D uint8 array")
            request.gray.height, request.gray.width = gray.shape
            request.gray.pixels = gray.tobytes()
        try:
            response = self._stub.Locate(request, metadata=self._metadata, timeout=timeout_s)
        except grpc.RpcError as error:
            raise ServiceError("Locate", error.code(), error.details()) from None
        return LocateResult(response)

    def session(self, map_name, camera, initial_pose=None, initial_t_ns=0, **options):
        """A tracking session (use it in a `with`); see Session for the options."""
        return Session(self, map_name, camera, initial_pose, initial_t_ns, **options)


class Session:
    """One Track stream. Options: step_rate_hz, variant, max_points (TrackingOptions);
    packet_ms (window of a packet, default 1 ms as evloc-replay), client_name, and the reconnect
    of evloc-replay: reconnect (attempts per outage, default 0: fail at once), backoff_ms (100),
    backoff_max_ms (2000), reconnect_max_s (60), stable_s (10), resume_prime_ms (100),
    resume_velocity_ms (100: a resumed session starts with the velocity of the last TRACKING poses
    within it, as evloc-replay --resume-velocity-ms; 0: at rest), seed; thin_while_searching
    (default True: while the server searches the map, send at most the events per second it
    announced in SessionStarted.searching_event_rate, as evloc-replay does; events_thinned counts
    the events left out)."""

    def __init__(self, client, map_name, camera, initial_pose, initial_t_ns, *, step_rate_hz=None,
                 variant=None, max_points=None, packet_ms=1.0, client_name="evloc-python",
                 reconnect=0, backoff_ms=100.0, backoff_max_ms=2000.0, reconnect_max_s=60.0,
                 stable_s=10.0, resume_prime_ms=100.0, resume_velocity_ms=100.0, seed=None,
                 thin_while_searching=True):
        api, _ = _stubs()
        self._client = client
        self._map_name = map_name
        self._camera = dict(camera)
        self._options = api.TrackingOptions()
        if step_rate_hz is not None:
            self._options.step_rate_hz = float(step_rate_hz)
        if variant is not None:
            self._options.variant = variant
        if max_points is not None:
            self._options.max_points = int(max_points)
        if not 0 < packet_ms <= 1000:
            raise ValueError("Session: packet_ms must be in (0, 1000]")
        self._packet_ns = int(round(packet_ms * 1e6))
        self._client_name = client_name
        if reconnect < 0 or backoff_ms <= 0 or backoff_max_ms < backoff_ms or reconnect_max_s < 0:
            raise ValueError("Session: reconnect >= 0, 0 < backoff_ms <= backoff_max_ms, "
                             "reconnect_max_s >= 0")
        self._reconnect = int(reconnect)
        self._backoff_ms = float(backoff_ms)
        self._backoff_max_ms = float(backoff_max_ms)
        self._reconnect_max_s = float(reconnect_max_s)
        self._stable_s = float(stable_s)
        self._prime_ns = int(round(resume_prime_ms * 1e6))
        if not 0 <= resume_velocity_ms <= 1000:
            raise ValueError("Session: resume_velocity_ms must be in [0, 1000]")
        self._velocity_ns = int(round(resume_velocity_ms * 1e6))
        # (t_ns, pose values) of the trailing run of TRACKING poses within the velocity window.
        self._tracking_run = collections.deque()
        self._random = random.Random(seed)
        self._start_pose = None if initial_pose is None else self._pose_values(initial_pose)
        self._start_t_ns = int(initial_t_ns)

        self._lock = threading.Condition()
        self._requests = None            # the current stream's request queue
        self._call = None
        self._history = collections.deque()   # (end_t_ns, EventPacket) since the last pose - prime
        self._unconfirmed = collections.deque()
        self._max_in_flight = 1
        self._poses = queue.Queue()
        self._last_pose = None           # (t_ns, pose values) of the last pose with a pose
        self._sessions = 0
        self._closed = False
        self._finished = False
        self._error = None
        self._reader = None
        self._last_end_ns = None
        self._pending = None             # the events of the last time stamp sent (send())
        self.started = None              # SessionStarted of the current session
        self.end = None                  # SessionEnd, when the server sent one
        self.reconnects = 0              # sessions resumed after a failure
        self._thin = bool(thin_while_searching)
        self._searching = False          # the newest update had no pose (the server searching)
        self.events_thinned = 0          # events left out while the server searched

    @staticmethod
    def _pose_values(pose):
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape == (4, 4):
            from evloc.tracking import _matrix_to_pose  # pylint: disable=import-outside-toplevel
            pose = np.asarray(_matrix_to_pose(pose))
        if pose.shape != (7,) or not np.all(np.isfinite(pose)):
            raise ValueError("Session: initial_pose must be 7 finite values (tx ty tz qx qy qz qw)"
                             " or a 4x4 matrix")
        return pose

    # -- the stream ------------------------------------------------------------------------
    def _resume_velocity(self):
        """The twist of the trailing TRACKING poses over the velocity window (evloc-replay's
        ResumeVelocity), or None when the last two poses are not both TRACKING. Under the lock."""
        run = self._tracking_run
        if self._velocity_ns == 0 or len(run) < 2:
            return None
        newest_t, newest = run[-1]
        older_t, older = run[0]
        for t_ns, pose in reversed(run):
            older_t, older = t_ns, pose
            if newest_t - t_ns >= self._velocity_ns:
                break
        if newest_t <= older_t:
            return None
        from evloc._native import _evloc  # pylint: disable=import-outside-toplevel
        return _evloc.body_twist(older, newest, (newest_t - older_t) * 1e-9)

    def _start_request(self, pose, t_ns, velocity=None):
        api, _ = _stubs()
        request = api.TrackRequest()
        start = request.start
        start.map_name = self._map_name
        _fill_camera(self._camera, start.camera)
        if pose is not None:
            r = start.initial_world_from_cam
            r.translation.x, r.translation.y, r.translation.z = (float(v) for v in pose[:3])
            r.rotation.x, r.rotation.y, r.rotation.z, r.rotation.w = (float(v) for v in pose[3:])
        if pose is not None and velocity is not None:
            v = start.initial_velocity
            v.linear.x, v.linear.y, v.linear.z = (float(x) for x in velocity[:3])
            v.angular.x, v.angular.y, v.angular.z = (float(x) for x in velocity[3:])
        start.initial_t_ns = int(t_ns)
        start.options.CopyFrom(self._options)
        start.client_name = self._client_name
        return request

    def _open(self, pose, t_ns, resume, velocity=None):
        """Starts a stream with a SessionStart at (pose, t_ns) and, when `resume`, the packets
        sent since resume_prime_ms before t_ns; returns the response iterator after
        SessionStarted. Raises grpc.RpcError."""
        requests = queue.Queue()
        requests.put(self._start_request(pose, t_ns, velocity))

        def iterate():
            while True:
                item = requests.get()
                if item is None:
                    return
                yield item

        call = self._client._stub.Track(iterate(), metadata=self._client._metadata)
        responses = iter(call)
        try:
            first = next(responses)
        except StopIteration:
            raise ServiceError("Track", None, "the stream ended before SessionStarted") from None
        if not first.HasField("started"):
            call.cancel()
            raise ServiceError("Track", None, "the first response is not SessionStarted")
        with self._lock:
            self._requests = requests
            self._call = call
            self.started = first.started
            self._searching = pose is None
            self._max_in_flight = max(1, min(first.started.queue_capacity // 2, 5))
            self._unconfirmed.clear()
            api, _ = _stubs()
            # Under the lock that send() takes: no packet is sent between this copy of the
            # history and the switch to the new stream.
            resend = [(end, packet) for end, packet in self._history
                      if end > t_ns - self._prime_ns] if resume else []
            for end_t_ns, packet in resend:
                requests.put(api.TrackRequest(events=packet))
                self._unconfirmed.append(end_t_ns)
            if self._closed:
                requests.put(None)
        return responses

    def __enter__(self):
        try:
            responses = self._open(self._start_pose, self._start_t_ns, False)
        except grpc.RpcError as error:
            raise ServiceError("SessionStart", error.code(), error.details()) from None
        self._session_started_at = time.monotonic()
        self._reader = threading.Thread(target=self._read, args=(responses,), daemon=True)
        self._reader.start()
        return self

    def __exit__(self, exc_type, *exc):
        if exc_type is not None:
            self.cancel()
        else:
            self.close()
            self.wait()

    def _read(self, responses):
        outage_start = None
        attempts = 0
        while True:
            try:
                for message in responses:
                    if message.HasField("pose"):
                        update = Pose(message.pose, self._sessions)
                        with self._lock:
                            self._searching = update.pose is None
                            if update.pose is not None:
                                self._last_pose = (update.t_ns, update.pose)
                            if update.pose is not None and update.status == Status.TRACKING:
                                self._tracking_run.append((update.t_ns, update.pose))
                                while (len(self._tracking_run) > 2 and update.t_ns -
                                       self._tracking_run[1][0] >= self._velocity_ns):
                                    self._tracking_run.popleft()
                            else:
                                self._tracking_run.clear()
                            while self._unconfirmed and self._unconfirmed[0] <= update.t_ns:
                                self._unconfirmed.popleft()
                            horizon = update.t_ns - self._prime_ns
                            while self._history and self._history[0][0] <= horizon:
                                self._history.popleft()
                            self._lock.notify_all()
                        self._poses.put(update)
                    elif message.HasField("end"):
                        self.end = SessionEnd(message.end)
                with self._lock:
                    complete = self._closed
                if complete:
                    break
                failure = ServiceError("Track", grpc.StatusCode.UNAVAILABLE,
                                       "the server ended the session before the end of the stream")
                code, pushback = grpc.StatusCode.UNAVAILABLE, None
            except grpc.RpcError as error:
                failure = ServiceError("Track", error.code(), error.details())
                code, pushback = error.code(), self._pushback(error)
            if self._reconnect == 0 or code not in TRANSIENT_CODES:
                self._fail(failure)
                return
            # A session that stayed up stable_s starts a new outage with a fresh backoff.
            now = time.monotonic()
            if outage_start is None or now - self._session_started_at >= self._stable_s:
                outage_start, attempts = now, 0
            responses = None
            while responses is None:
                attempts += 1
                delay = self._backoff(attempts, code, pushback)
                if (delay is None or attempts > self._reconnect or
                        time.monotonic() + delay - outage_start > self._reconnect_max_s):
                    self._fail(ServiceError(
                        "Track", code, f"gave up reconnecting after {attempts - 1} attempts "
                        f"({failure.details})"))
                    return
                time.sleep(delay)
                # Wait for a connection (at least backoff_ms), so that an attempt does not fail
                # at once while the channel is still moving to another server.
                try:
                    grpc.channel_ready_future(self._client._channel).result(
                        timeout=max(delay, self._backoff_ms / 1000.0))
                except grpc.FutureTimeoutError:
                    code, pushback = grpc.StatusCode.UNAVAILABLE, None
                    continue
                with self._lock:
                    if self._last_pose is not None:
                        t_ns, pose = self._last_pose
                    else:
                        t_ns, pose = self._start_t_ns, self._start_pose
                    velocity = self._resume_velocity()
                try:
                    responses = self._open(pose, t_ns, True, velocity)
                except (grpc.RpcError, ServiceError) as error:
                    code = error.code() if isinstance(error, grpc.RpcError) else error.code
                    pushback = self._pushback(error) if isinstance(error, grpc.RpcError) else None
                    if code not in TRANSIENT_CODES and code is not None:
                        self._fail(ServiceError("Track", code, str(error)))
                        return
            self._sessions += 1
            self.reconnects += 1
            self._session_started_at = time.monotonic()
        with self._lock:
            self._finished = True
            self._lock.notify_all()
        self._poses.put(None)

    @staticmethod
    def _pushback(error):
        """The server's grpc-retry-pushback-ms, seconds (negative: do not retry), or None."""
        try:
            for key, value in error.trailing_metadata() or ():
                if key == "grpc-retry-pushback-ms":
                    return int(value) / 1000.0
        except (ValueError, AttributeError):
            return -1.0
        return None

    def _backoff(self, attempt, code, pushback):
        """Full jitter in [0, min(cap, base 2^(k-1))]; overloaded: at least half the ceiling; the
        server's pushback when it gave one (None: do not retry)."""
        if pushback is not None:
            return None if pushback < 0 else pushback
        ceiling = min(self._backoff_max_ms, self._backoff_ms * 2 ** (attempt - 1)) / 1000.0
        low = ceiling / 2 if code == grpc.StatusCode.RESOURCE_EXHAUSTED else 0.0
        return self._random.uniform(low, ceiling)

    def _fail(self, error):
        with self._lock:
            self._error = error
            self._finished = True
            self._lock.notify_all()
        self._poses.put(None)

    # -- the caller's side -----------------------------------------------------------------
    def send(self, events, end_t_ns=None):
        """Sends time-ordered events (a structured array with fields t, x, y, p, a dict, or a
        tuple (t, x, y, p)) in PACKED packets of packet_ms windows. The last packet declares
        every event up to end_t_ns given; without end_t_ns, the events of the last time stamp
        are held back until the next send() or close(). Waits while more than
        a few packets are unconfirmed by poses (as evloc-replay paces), so that the server's
        queue never overflows."""
        from evloc.tracking import _native_events  # pylint: disable=import-outside-toplevel
        t, x, y, p = _native_events(events)
        if self._pending is not None:
            t, x, y, p = (np.concatenate((a, b)) for a, b in zip(self._pending, (t, x, y, p)))
            self._pending = None
        if len(t) and end_t_ns is None:
            # The events of the last time stamp wait for the next call (or close()): more events
            # of that nanosecond may follow, and a packet's end promises there are none.
            tail = int(np.searchsorted(t, t[-1]))
            self._pending = (t[tail:], x[tail:], y[tail:], p[tail:])
            t, x, y, p = t[:tail], x[:tail], y[:tail], p[:tail]
            if not len(t):
                return
            end_t_ns = int(self._pending[0][0]) - 1
        self._send(t, x, y, p, end_t_ns)

    def _send(self, t, x, y, p, end_t_ns):
        api, _ = _stubs()
        if len(t) == 0 and end_t_ns is None:
            return
        last = int(t[-1]) if len(t) else int(end_t_ns)
        end_t_ns = last if end_t_ns is None else int(end_t_ns)
        if end_t_ns < last:
            raise ValueError("Session.send: end_t_ns lies before the last event")
        if self._last_end_ns is not None and len(t) and t[0] <= self._last_end_ns:
            raise ValueError(f"Session.send: the events start at {int(t[0])} ns, not after the "
                             f"previous packet's end {self._last_end_ns} ns")
        origin = self._last_end_ns if self._last_end_ns is not None else (
            int(t[0]) - 1 if len(t) else end_t_ns - 1)
        # Packet k holds the events in (origin + k w, origin + (k + 1) w].
        window = np.maximum((t - origin - 1) // self._packet_ns, 0)
        bounds = np.flatnonzero(np.diff(window)) + 1
        starts = np.concatenate(([0], bounds)) if len(t) else np.array([], dtype=np.int64)
        stops = np.concatenate((bounds, [len(t)])) if len(t) else np.array([], dtype=np.int64)
        with self._lock:
            rate = self.started.searching_event_rate if self._thin and self._searching else 0
        packets = []
        for begin, stop in zip(starts, stops):
            base = origin + int(window[begin]) * self._packet_ns
            end = min(base + self._packet_ns, end_t_ns)
            stride = thinning_stride(stop - begin, end - base, rate)
            kept = slice(begin, stop, stride)
            self.events_thinned += (stop - begin) - len(range(begin, stop, stride))
            packet = api.EventPacket(encoding=api.EVENT_ENCODING_PACKED, time_base_ns=base,
                                     end_t_ns=end,
                                     data=encode_packed(t[kept], x[kept], y[kept], p[kept], base))
            packets.append(packet)
        if not packets or packets[-1].end_t_ns < end_t_ns:
            packets.append(api.EventPacket(encoding=api.EVENT_ENCODING_PACKED,
                                           time_base_ns=end_t_ns, end_t_ns=end_t_ns))
        packets[-1].end_t_ns = end_t_ns
        for packet in packets:
            with self._lock:
                # Pace by the poses; without one for 20 ms one more packet goes out.
                if len(self._unconfirmed) >= self._max_in_flight and not self._finished:
                    self._lock.wait(0.02)
                if self._error is not None:
                    raise self._error
                if self._closed:
                    raise ValueError("Session.send: the session is closed")
                self._history.append((packet.end_t_ns, packet))
                self._unconfirmed.append(packet.end_t_ns)
                self._requests.put(api.TrackRequest(events=packet))
        self._last_end_ns = end_t_ns

    def close(self, end_t_ns=None):
        """No more events: the server tracks what it has, sends SessionEnd and ends the stream.
        Poses keep arriving until then (iterate poses()). `end_t_ns`: the time up to which the
        sensor saw nothing more (default: the last event's), so that the steps due by then run."""
        if not self._closed and (self._pending is not None or end_t_ns is not None):
            pending, self._pending = self._pending, None
            if pending is None:
                empty = np.empty(0, dtype=np.int64)
                pending = (empty, empty.astype(np.uint16), empty.astype(np.uint16),
                           empty.astype(np.int8))
            self._send(*pending, end_t_ns)
        with self._lock:
            if not self._closed:
                self._closed = True
                if self._requests is not None:
                    self._requests.put(None)

    def cancel(self):
        """Ends the stream at once."""
        with self._lock:
            self._closed = True
            self._reconnect = 0
            if self._call is not None:
                self._call.cancel()

    def wait(self, timeout=None):
        """Waits for the end of the session; raises the session's error (ServiceError)."""
        with self._lock:
            self._lock.wait_for(lambda: self._finished, timeout)
            if self._error is not None:
                raise self._error

    def poses(self, timeout=None):
        """The pose updates, as they arrive, until the session ends (after close()); raises
        ServiceError when the session failed (and could not be resumed). `timeout`: most seconds
        to wait for one update (queue.Empty beyond)."""
        while True:
            update = self._poses.get(timeout=timeout)
            if update is None:
                self._poses.put(None)  # later calls end at once too
                with self._lock:
                    if self._error is not None:
                        raise self._error
                return
            yield update
