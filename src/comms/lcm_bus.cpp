#include "slamd/comms/lcm_bus.hpp"

#include <pthread.h>

#include "slamd/common/log.hpp"

namespace slamd {

LcmBus::LcmBus(const std::string& url) : url_(url), lcm_(url) {
  if (!lcm_.good()) {
    throw std::runtime_error("cannot start LCM with URL '" + (url.empty() ? "<default>" : url) +
                             "' (is there a network interface with a multicast route? try "
                             "'ip route add 224.0.0.0/4 dev lo' for a single machine)");
  }
}

LcmBus::~LcmBus() { stopHandling(); }

bool LcmBus::publish(const std::string& channel, const std::vector<std::uint8_t>& bytes) {
  if (lcm_.publish(channel, bytes.data(), static_cast<unsigned int>(bytes.size())) != 0) {
    const auto failures = publish_failures_.fetch_add(1, std::memory_order_relaxed) + 1;
    if (failures <= 5 || failures % 1000 == 0) {
      SLAMD_LOG_WARN("lcm") << "publish on " << channel << " failed (" << failures
                            << " failures so far)";
    }
    return false;
  }
  return true;
}

void LcmBus::subscribeRaw(const std::string& channel, RawHandler handler, int queue_capacity) {
  auto subscription = std::make_unique<Subscription>(Subscription{this, std::move(handler)});
  lcm::Subscription* lcm_subscription =
      lcm_.subscribeFunction(channel, &LcmBus::onRaw, subscription.get());
  if (lcm_subscription == nullptr) {
    throw std::runtime_error("cannot subscribe to LCM channel '" + channel + "'");
  }
  lcm_subscription->setQueueCapacity(queue_capacity);
  subscriptions_.push_back(std::move(subscription));
}

void LcmBus::onRaw(const lcm::ReceiveBuffer* buffer, const std::string& channel,
                   Subscription* subscription) {
  subscription->handler(channel, static_cast<const std::uint8_t*>(buffer->data), buffer->data_size,
                        buffer->recv_utime);
}

void LcmBus::startHandling() {
  if (handling_.exchange(true)) return;
  handler_thread_ = std::thread([this] {
    pthread_setname_np(pthread_self(), "slamd:lcm-bus");
    // Short timeouts so stopHandling() is noticed within 50 ms.
    while (handling_.load(std::memory_order_acquire)) {
      if (lcm_.handleTimeout(50) < 0) {
        SLAMD_LOG_ERROR("lcm") << "LCM handle failed; stopping the receive thread";
        break;
      }
    }
  });
}

void LcmBus::stopHandling() {
  handling_.store(false, std::memory_order_release);
  if (handler_thread_.joinable()) handler_thread_.join();
}

int LcmBus::handle(int timeout_ms) { return lcm_.handleTimeout(timeout_ms); }

void LcmBus::countMalformed(const std::string& channel) {
  std::uint64_t count = 0;
  {
    std::lock_guard<std::mutex> lock(malformed_mutex_);
    count = ++malformed_by_channel_[channel];
  }
  if (count <= 5 || count % 1000 == 0) {
    SLAMD_LOG_WARN("lcm") << "malformed message on " << channel << " (" << count << " so far)";
  }
}

std::uint64_t LcmBus::malformedCount(const std::string& channel) const {
  std::lock_guard<std::mutex> lock(malformed_mutex_);
  const auto it = malformed_by_channel_.find(channel);
  return it == malformed_by_channel_.end() ? 0 : it->second;
}

std::uint64_t LcmBus::malformedTotal() const {
  std::lock_guard<std::mutex> lock(malformed_mutex_);
  std::uint64_t total = 0;
  for (const auto& entry : malformed_by_channel_) total += entry.second;
  return total;
}

}  // namespace slamd
