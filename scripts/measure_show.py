#!/usr/bin/env python3
"""Measures procam play's OSC control and raw-frame input on this machine (docs/show.md).

  scripts/measure_show.py PROCAM_BINARY [SECONDS]

tiny_box (80 patches) as a scene file and rig, `procam play --desired stdin:64x48 --fps 30 --osc
127.0.0.1:0`, frames piped at 60 per second (twice the show's rate, so about half are replaced),
and, over OSC from 127.0.0.1: /procam/status round trips, and fades to black and back at once,
each followed by a status. Prints the status round trip (median, 95th percentile), the frames
between a command's arrival and the frame that applied it, and the input's frames received,
replaced and shown. Everything on 127.0.0.1.
"""
import json, os, socket, struct, subprocess, sys, tempfile, threading, time


def pad(b):
    b += b"\0"
    return b + b"\0" * (-len(b) % 4)


def osc(address, *floats):
    return pad(address.encode()) + pad(("," + "f" * len(floats)).encode()) + b"".join(
        struct.pack(">f", f) for f in floats)


def main():
    binary = sys.argv[1]
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 8.0
    work = tempfile.mkdtemp(prefix="procam-show-")
    subprocess.run([binary, "scene", "write", "tiny_box", "--patches", "80", "--out", work],
                   check=True, stdout=subprocess.DEVNULL)
    scene = os.path.join(work, "tiny_box.json")
    with open(scene) as f:
        data = json.load(f)
    with open(os.path.join(work, "rig.json"), "w") as f:
        json.dump({"format_version": 1, "camera": {"model": data["cameras"][0]["model"]},
                   "projectors": data["projectors"]}, f)
    log = open(os.path.join(work, "play.log"), "w")
    play = subprocess.Popen([binary, "play", scene, "--rig", work, "--desired", "stdin:64x48",
                             "--fps", "30", "--osc", "127.0.0.1:0", "--display", "memory,memory",
                             "--out", os.path.join(work, "play")],
                            stdin=subprocess.PIPE, stdout=log, stderr=subprocess.STDOUT)
    sent = [0]
    done = threading.Event()

    def feed():
        k = 0
        start = time.monotonic()
        while not done.is_set() and time.monotonic() - start < seconds + 60:
            level = 40 + (k * 7) % 180
            try:
                play.stdin.write(bytes([level, 120, 255 - level]) * (64 * 48))
                play.stdin.flush()
            except BrokenPipeError:
                break
            k += 1
            sent[0] = k
            time.sleep(max(0.0, start + k / 60.0 - time.monotonic()))

    feeder = threading.Thread(target=feed)
    feeder.start()
    port = 0
    for _ in range(1200):
        with open(os.path.join(work, "play.log")) as f:
            text = f.read()
        if "osc: listening on 127.0.0.1:" in text:
            port = int(text.split("osc: listening on 127.0.0.1:")[1].split()[0])
            break
        time.sleep(0.05)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.5)

    def status():
        t = time.perf_counter()
        sock.sendto(osc("/procam/status"), ("127.0.0.1", port))
        reply, _ = sock.recvfrom(2048)
        return time.perf_counter() - t, struct.unpack(">i", reply[28:32])[0]

    for _ in range(600):  # the show under way
        try:
            if status()[1] >= 5:
                break
        except socket.timeout:
            pass
        time.sleep(0.05)
    rtts = []
    for _ in range(200):
        rtts.append(status()[0])
        time.sleep(0.005)
    reported = []
    end = time.monotonic() + seconds
    k = 0
    while time.monotonic() < end:
        sock.sendto(osc("/procam/fade", 0.0 if k % 2 == 0 else 1.0, 0.0), ("127.0.0.1", port))
        reported.append(status()[1])
        k += 1
        time.sleep(0.2)
    sock.sendto(osc("/procam/stop"), ("127.0.0.1", port))
    done.set()
    play.wait(timeout=60)
    feeder.join()
    result = json.load(open(os.path.join(work, "play", "result.json")))
    frames = result["frames"]
    lag_received, lag_status = [], []
    fades = 0
    for frame in frames:
        for command in frame.get("osc", []):
            if command["command"].startswith("fade"):
                lag_received.append(frame["frame"] - command["received_frame"])
                lag_status.append(frame["frame"] - reported[fades])
                fades += 1
    rtts.sort()
    shown = len({f["source"] for f in frames})
    print(f"status round trip: median {1e3 * rtts[len(rtts) // 2]:.3f} ms, "
          f"95th percentile {1e3 * rtts[int(0.95 * len(rtts))]:.3f} ms ({len(rtts)} requests)")
    print(f"fade commands: {fades}; frames from arrival to applied: "
          f"{ {v: lag_received.count(v) for v in sorted(set(lag_received))} }; "
          f"from the status frame: { {v: lag_status.count(v) for v in sorted(set(lag_status))} }")
    print(f"frames shown {result['frames_shown']}, dropped {result['frames_dropped']}, "
          f"median solve {result['median_ms']['solve']:.2f} ms, total {result['median_ms']['total']:.2f} ms")
    print(f"input: sent {sent[0]}, received {result['frames_received']}, "
          f"replaced {result['frames_replaced']}, shown {shown}")


if __name__ == "__main__":
    main()
