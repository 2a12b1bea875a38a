// serial_tcp: one UART served raw on one TCP port (see __init__.py and
// docs/esp32-radar.md). Everything runs in the main loop, never blocks, and
// uses memory fixed at setup: a radar's bytes must keep flowing whatever a
// client or the network does.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>

#include "esphome/components/socket/socket.h"
#include "esphome/components/uart/uart.h"
#include "esphome/core/component.h"
#include "esphome/core/defines.h"

#ifdef USE_BINARY_SENSOR
#include "esphome/components/binary_sensor/binary_sensor.h"
#endif

namespace esphome::serial_tcp {

// Clients per port at most (max_clients in YAML is checked against it).
static constexpr size_t MAX_CLIENTS = 4;

class SerialTcpServer : public Component, public uart::UARTDevice {
 public:
  void set_port(uint16_t port) { this->port_ = port; }
  void set_buffer_size(size_t size) { this->buffer_size_ = size; }
  void set_max_clients(size_t count) { this->max_clients_ = count < MAX_CLIENTS ? count : MAX_CLIENTS; }
#ifdef USE_BINARY_SENSOR
  void set_connected_sensor(binary_sensor::BinarySensor *sensor) { this->connected_sensor_ = sensor; }
#endif

  void setup() override;
  void loop() override;
  void dump_config() override;
  void on_shutdown() override;
  // The listening socket needs the network stack up.
  float get_setup_priority() const override { return setup_priority::AFTER_WIFI; }

 protected:
  struct Client {
    std::unique_ptr<socket::Socket> sock;
    // Position in the stream of UART bytes up to which this client was sent.
    uint64_t sent{0};
  };

  bool open_listener_();
  void accept_clients_();
  void read_uart_();
  void send_to_clients_();
  void receive_from_clients_();
  void drop_client_(Client &client, const char *why, int error);
  void remove_dropped_();
  void publish_connected_();

  uint16_t port_{0};
  size_t buffer_size_{1024};
  size_t max_clients_{1};

  std::unique_ptr<socket::ListenSocket> listener_;
  std::array<Client, MAX_CLIENTS> clients_{};
  size_t client_count_{0};

  // Ring of the last buffer_size_ bytes read from the UART. `head_` counts
  // every byte ever read, so a client's lag is head_ - sent, and a client more
  // than one buffer behind has lost the oldest bytes (counted in dropped_).
  std::unique_ptr<uint8_t[]> ring_;
  uint64_t head_{0};
  uint32_t dropped_{0};
  uint32_t refused_{0};

#ifdef USE_BINARY_SENSOR
  binary_sensor::BinarySensor *connected_sensor_{nullptr};
#endif
};

}  // namespace esphome::serial_tcp
