#include "serial_tcp.h"

#include <algorithm>
#include <cerrno>

#include "esphome/core/log.h"

namespace esphome::serial_tcp {

static const char *const TAG = "serial_tcp";

// Bytes moved per step: a stack buffer, small enough for the loop task's stack.
static constexpr size_t CHUNK = 128;
// Client-to-UART bytes taken per client per loop: commands are a few dozen
// bytes, so this only stops a flooding client from holding the loop.
static constexpr size_t MAX_IN_PER_LOOP = 4 * CHUNK;

static bool would_block(ssize_t result) {
  return result < 0 && (errno == EWOULDBLOCK || errno == EAGAIN);
}

void SerialTcpServer::setup() {
  this->ring_ = std::make_unique<uint8_t[]>(this->buffer_size_);
  if (!this->open_listener_()) {
    this->mark_failed();
    return;
  }
  this->publish_connected_();
}

bool SerialTcpServer::open_listener_() {
  this->listener_ = socket::socket_ip_loop_monitored(SOCK_STREAM, 0);
  if (this->listener_ == nullptr) {
    ESP_LOGE(TAG, "port %u: no socket", this->port_);
    return false;
  }
  int enable = 1;
  this->listener_->setsockopt(SOL_SOCKET, SO_REUSEADDR, &enable, sizeof(enable));
  if (this->listener_->setblocking(false) != 0) {
    ESP_LOGE(TAG, "port %u: cannot make the socket non-blocking", this->port_);
    return false;
  }
  struct sockaddr_storage address;
  socklen_t length = socket::set_sockaddr_any((struct sockaddr *) &address, sizeof(address), this->port_);
  if (length == 0 || this->listener_->bind((struct sockaddr *) &address, length) != 0) {
    ESP_LOGE(TAG, "port %u: bind failed (errno %d)", this->port_, errno);
    return false;
  }
  if (this->listener_->listen(1) != 0) {
    ESP_LOGE(TAG, "port %u: listen failed (errno %d)", this->port_, errno);
    return false;
  }
  return true;
}

void SerialTcpServer::loop() {
  this->accept_clients_();
  this->read_uart_();
  this->send_to_clients_();
  this->receive_from_clients_();
  this->remove_dropped_();
}

void SerialTcpServer::accept_clients_() {
  if (!this->listener_->ready())
    return;
  // Accept until none is waiting (the socket's ready() asks us to drain it).
  while (true) {
    struct sockaddr_storage peer;
    socklen_t peer_length = sizeof(peer);
    std::unique_ptr<socket::Socket> sock = this->listener_->accept((struct sockaddr *) &peer, &peer_length);
    if (sock == nullptr)
      return;
    if (this->client_count_ >= this->max_clients_) {
      // A second reader would get the same bytes and interleave its commands
      // with the first one's: refuse it, the one already here keeps the radar.
      this->refused_++;
      ESP_LOGW(TAG, "port %u: refused a client (%u of %u connected)", this->port_,
               (unsigned) this->client_count_, (unsigned) this->max_clients_);
      sock->close();
      continue;
    }
    sock->setblocking(false);
    int enable = 1;
    sock->setsockopt(IPPROTO_TCP, TCP_NODELAY, &enable, sizeof(enable));  // a frame is small: send it now
    Client &client = this->clients_[this->client_count_++];
    client.sock = std::move(sock);
    client.sent = this->head_;  // only bytes from now on: an old half frame helps nobody
    ESP_LOGI(TAG, "port %u: client connected (%u)", this->port_, (unsigned) this->client_count_);
    this->publish_connected_();
  }
}

void SerialTcpServer::read_uart_() {
  // Read everything the UART holds, even with no client: its own buffer must
  // never fill, or the first frames a new client gets would be stale.
  const size_t mask = this->buffer_size_ - 1;
  size_t waiting = this->available();
  while (waiting > 0) {
    size_t index = this->head_ & mask;
    size_t length = std::min(waiting, this->buffer_size_ - index);  // up to the ring's end
    if (!this->read_array(this->ring_.get() + index, length))
      break;
    this->head_ += length;
    waiting -= length;
  }
}

void SerialTcpServer::send_to_clients_() {
  const size_t mask = this->buffer_size_ - 1;
  for (size_t i = 0; i < this->client_count_; i++) {
    Client &client = this->clients_[i];
    if (client.sock == nullptr)
      continue;
    if (this->head_ - client.sent > this->buffer_size_) {
      // This client fell more than a buffer behind (a Wi-Fi stall): the oldest
      // bytes are overwritten. Skip them; the bridge's parser resynchronises
      // on the next frame header.
      uint64_t lost = this->head_ - this->buffer_size_ - client.sent;
      this->dropped_ += (uint32_t) lost;
      client.sent = this->head_ - this->buffer_size_;
      ESP_LOGW(TAG, "port %u: client too slow, %u bytes dropped", this->port_, (unsigned) lost);
    }
    while (client.sent < this->head_) {
      size_t index = client.sent & mask;
      size_t length = (size_t) std::min<uint64_t>(this->head_ - client.sent, this->buffer_size_ - index);
      ssize_t written = client.sock->write(this->ring_.get() + index, length);
      if (would_block(written))
        break;  // the socket's send buffer is full: the rest waits in the ring
      if (written <= 0) {
        this->drop_client_(client, "send failed", errno);
        break;
      }
      client.sent += (uint64_t) written;
    }
  }
}

void SerialTcpServer::receive_from_clients_() {
  uint8_t chunk[CHUNK];
  for (size_t i = 0; i < this->client_count_; i++) {
    Client &client = this->clients_[i];
    size_t taken = 0;
    while (client.sock != nullptr && taken < MAX_IN_PER_LOOP) {
      ssize_t got = client.sock->read(chunk, sizeof(chunk));
      if (would_block(got))
        break;
      if (got == 0) {
        this->drop_client_(client, "closed by the client", 0);
        break;
      }
      if (got < 0) {
        this->drop_client_(client, "receive failed", errno);
        break;
      }
      this->write_array(chunk, (size_t) got);
      taken += (size_t) got;
    }
  }
}

void SerialTcpServer::remove_dropped_() {
  // Compact the array, keeping the order of the clients still here.
  size_t kept = 0;
  for (size_t i = 0; i < this->client_count_; i++) {
    if (this->clients_[i].sock == nullptr)
      continue;
    if (kept != i)
      this->clients_[kept] = std::move(this->clients_[i]);
    kept++;
  }
  if (kept != this->client_count_) {
    this->client_count_ = kept;
    this->publish_connected_();
  }
}

void SerialTcpServer::drop_client_(Client &client, const char *why, int error) {
  (void) why;  // unused when the log level is below INFO
  (void) error;
  ESP_LOGI(TAG, "port %u: client gone (%s, errno %d)", this->port_, why, error);
  client.sock->close();
  client.sock.reset();
}

void SerialTcpServer::publish_connected_() {
#ifdef USE_BINARY_SENSOR
  if (this->connected_sensor_ != nullptr)
    this->connected_sensor_->publish_state(this->client_count_ > 0);
#endif
}

void SerialTcpServer::on_shutdown() {
  for (size_t i = 0; i < this->client_count_; i++) {
    if (this->clients_[i].sock != nullptr)
      this->clients_[i].sock->close();
  }
  this->client_count_ = 0;
  if (this->listener_ != nullptr)
    this->listener_->close();
}

void SerialTcpServer::dump_config() {
  ESP_LOGCONFIG(TAG,
                "Serial TCP server:\n"
                "  Port: %u\n"
                "  Buffer: %u bytes\n"
                "  Clients at most: %u",
                this->port_, (unsigned) this->buffer_size_, (unsigned) this->max_clients_);
  ESP_LOGCONFIG(TAG, "  Connected: %u, refused: %u, bytes dropped: %u", (unsigned) this->client_count_,
                (unsigned) this->refused_, (unsigned) this->dropped_);
#ifdef USE_BINARY_SENSOR
  LOG_BINARY_SENSOR("  ", "Connected", this->connected_sensor_);
#endif
}

}  // namespace esphome::serial_tcp
