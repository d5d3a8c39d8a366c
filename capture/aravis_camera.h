#pragma once
// The Aravis backend ("aravis:" URIs): GenICam cameras over GigE Vision and USB3 Vision, and
// Aravis's in-process Fake camera (device id Fake_1) for tests. Exposure, gain and pixel format
// through the GenICam features ExposureTime (µs), Gain (dB by the SFNC) and PixelFormat; frames
// through an ArvStream with `buffers` preallocated buffers; a software trigger per grab when the
// camera supports it (trigger=software, the default where available), free-running otherwise;
// a triggered frame that arrives incomplete (lost packets) is triggered again until the grab's
// timeout.
// ExposureTime and Gain are read when the camera opens and after each change procam makes, not
// at every grab (a grab costs no control transaction): a camera changed behind procam's back
// reports stale values in Frame until the next SetExposure or SetGain.
// A camera whose control channel is lost (Aravis's "control-lost" signal, e.g. a GigE camera
// that stops answering heartbeats) raises CameraDisconnected from the next call; so does a
// request that goes unanswered (after Aravis's retries), and closing the camera after one skips
// the stop command, which would only be retried too.
//
// URIs:
//   aravis:<device id>?trigger=auto|software|free&buffers=8&format=Mono8
//       Device ids are what `procam cameras` (or arv-tool-0.8) prints; Aravis finds the device
//       by its id, which for a GigE Vision camera means a discovery broadcast on every
//       interface. Ids beginning with "Fake" open only the Fake interface and switch GigE
//       Vision discovery off for the process, so tests never broadcast. Note that the
//       in-process Fake camera free-runs at 25 Hz whatever its trigger settings.
//   aravis:gv:<IPv4 address>?interface=<IPv4 address>&packet_size=8192&trigger=...&buffers=...
//       &format=...
//       A GigE Vision camera opened by its address, with discovery off: every packet goes to
//       that address, none is broadcast. `interface` is the local address to talk from; by
//       default the one the kernel routes the camera's address from (127.0.0.1 for a camera
//       on loopback, such as the emulator of gige_emulator.h). `packet_size` (any GigE Vision
//       camera, by id or address) sets the stream packet size.

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "capture/camera.h"

typedef struct _ArvCamera ArvCamera;

namespace procam {

struct AravisCameraOptions {
  std::string device_id;  // as Aravis lists it; exactly one of device_id and gige_address
  std::string gige_address;  // IPv4 address of a GigE Vision camera, opened without discovery
  std::string interface_address;  // with gige_address: local IPv4 address; empty = routed one
  std::string trigger =
      "auto";       // "software", "free" (free-running), "auto" = software if supported
  int buffers = 8;  // stream buffers, [2, 64]
  // GigE Vision stream packet size, bytes (GevSCPSPacketSize), [576, 65000]; 0 = the camera's
  // (or what Aravis negotiates). Larger packets (jumbo frames, where the network allows them)
  // cost the receiving host less per frame.
  int packet_size = 0;
  std::optional<PixelFormat> format;  // nullopt: keep the camera's (Mono8 when it is not decodable)
  bool Check(std::string* why) const;
};

// Reads the URI's keys. Throws IoError naming the URI and key.
AravisCameraOptions AravisCameraOptionsFromUri(const CameraUri& uri);

// Whether `text` is a dotted IPv4 address (inet_pton), as aravis:gv: URIs and the GigE
// emulator's address take.
bool IsIpv4Address(const std::string& text);

class AravisCamera : public Camera {
 public:
  // Opens the camera and configures acquisition and trigger. Throws IoError naming the device.
  explicit AravisCamera(const AravisCameraOptions& options);
  ~AravisCamera() override;
  AravisCamera(const AravisCamera&) = delete;
  AravisCamera& operator=(const AravisCamera&) = delete;

  CameraInfo Info() const override;
  CameraSettings Settings() const override;
  std::vector<PixelFormat> SupportedPixelFormats() const override;
  void SetExposure(double exposure_us) override;
  void SetGain(double gain) override;
  void SetPixelFormat(PixelFormat format) override;
  void Start() override;
  void Stop() override;
  Frame Grab(std::chrono::milliseconds timeout) override;
  int DropBufferedFrames() override;

  // The underlying camera, owned by this object: for tests that drive the Fake camera's
  // registers or emit its signals.
  ArvCamera* handle() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Aravis's (PFNC) code of a pixel format procam decodes, and back; nullopt for a code procam
// does not decode or a format GenICam has no code for here (MJPEG).
std::optional<PixelFormat> PixelFormatFromPfnc(uint32_t code);
std::optional<uint32_t> PfncFromPixelFormat(PixelFormat format);

// Cameras Aravis finds: USB3 Vision always, GigE Vision when options.gige_discovery (a
// broadcast on every interface), the Fake camera when options.include_virtual.
std::vector<CameraInfo> ListAravisCameras(const ListCamerasOptions& options);

// The "aravis" backend for the registry.
CameraBackend AravisCameraBackend();

}  // namespace procam
