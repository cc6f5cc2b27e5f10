//! The byte transports under the link: UDP (out, in, broadcast), TCP
//! (client, server), serial.
//!
//! `udpin` replies to its peer, and the peer is chosen by the session, not
//! by whoever sent the last datagram: [`Transport::read`] reports the sender,
//! and the session calls [`Transport::follow`] only for a sender whose
//! datagram held a well-formed MAVLink 2 frame (signed and verified when
//! signing is on). A stray or hostile datagram cannot divert the poses.
//! `udpbcast` locks on to the first such sender the same way.

use super::address::Address;
use std::io;
use std::net::SocketAddr;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio_serial::SerialPortBuilderExt;

pub(crate) enum Transport {
    Udp {
        socket: UdpSocket,
        /// Where to send; for `udpin`, the sender of the last accepted frame.
        peer: Option<SocketAddr>,
        /// `udpin`: the peer may change (see [`Transport::follow`]).
        follow_sender: bool,
        /// `udpbcast`: the first accepted sender becomes the peer
        /// (pymavlink's lock-on); cleared once locked.
        lock_on_reply: bool,
    },
    Tcp(TcpStream),
    Serial(tokio_serial::SerialStream),
}

async fn resolve(host_port: &str) -> io::Result<SocketAddr> {
    tokio::net::lookup_host(host_port)
        .await?
        .next()
        .ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::AddrNotAvailable,
                format!("{host_port}: no address"),
            )
        })
}

impl Transport {
    pub async fn open(address: &Address) -> io::Result<Self> {
        match address {
            Address::UdpOut(hp) => {
                let dest = resolve(hp).await?;
                let bind: SocketAddr = if dest.is_ipv4() {
                    ([0, 0, 0, 0], 0).into()
                } else {
                    (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
                };
                Ok(Self::Udp {
                    socket: UdpSocket::bind(bind).await?,
                    peer: Some(dest),
                    follow_sender: false,
                    lock_on_reply: false,
                })
            }
            Address::UdpIn(hp) => Ok(Self::Udp {
                socket: UdpSocket::bind(resolve(hp).await?).await?,
                peer: None,
                follow_sender: true,
                lock_on_reply: false,
            }),
            Address::UdpBcast(hp) => {
                let dest = resolve(hp).await?;
                let socket = UdpSocket::bind(SocketAddr::from(([0, 0, 0, 0], 0))).await?;
                // Without SO_BROADCAST a send to a broadcast address fails (EACCES).
                socket.set_broadcast(true)?;
                Ok(Self::Udp {
                    socket,
                    peer: Some(dest),
                    follow_sender: false,
                    lock_on_reply: true,
                })
            }
            Address::TcpIn(hp) => {
                // Bound for one client: while it is served, others are
                // refused; after it hangs up the link reopens and listens again.
                let listener = TcpListener::bind(resolve(hp).await?).await?;
                tracing::info!(address = %address, "mavlink link: waiting for a TCP client");
                let (s, from) = listener.accept().await?;
                tracing::info!(%from, "mavlink link: TCP client connected");
                s.set_nodelay(true)?;
                Ok(Self::Tcp(s))
            }
            Address::TcpOut(hp) => {
                let s = TcpStream::connect(resolve(hp).await?).await?;
                s.set_nodelay(true)?;
                Ok(Self::Tcp(s))
            }
            Address::Serial { device, baud } => {
                let port = tokio_serial::new(device, *baud)
                    .data_bits(tokio_serial::DataBits::Eight)
                    .parity(tokio_serial::Parity::None)
                    .stop_bits(tokio_serial::StopBits::One)
                    .flow_control(tokio_serial::FlowControl::None)
                    .open_native_async()
                    .map_err(io::Error::from)?;
                Ok(Self::Serial(port))
            }
        }
    }

    /// Datagram transports deliver whole frames per read.
    pub fn is_datagram(&self) -> bool {
        matches!(self, Self::Udp { .. })
    }

    /// Reads what is available, and who sent it (UDP). `Ok((0, _))` on a
    /// stream: the peer hung up.
    pub async fn read(&mut self, buf: &mut [u8]) -> io::Result<(usize, Option<SocketAddr>)> {
        match self {
            Self::Udp { socket, .. } => {
                let (n, from) = socket.recv_from(buf).await?;
                Ok((n, Some(from)))
            }
            Self::Tcp(s) => s.read(buf).await.map(|n| (n, None)),
            Self::Serial(s) => s.read(buf).await.map(|n| (n, None)),
        }
    }

    /// `udpin`: replies go to `from` from now on. Returns the peer it
    /// replaces (`Some(None)`: the first peer) when the peer changed; `None`
    /// when it did not, or when this transport does not follow senders.
    pub fn follow(&mut self, from: SocketAddr) -> Option<Option<SocketAddr>> {
        match self {
            Self::Udp {
                peer,
                follow_sender: true,
                ..
            } if *peer != Some(from) => Some(peer.replace(from)),
            Self::Udp {
                peer,
                lock_on_reply,
                ..
            } if *lock_on_reply => {
                *lock_on_reply = false;
                Some(peer.replace(from))
            }
            _ => None,
        }
    }

    /// Writes one frame. `Ok(false)`: nowhere to send yet (`udpin` before the
    /// peer spoke).
    pub async fn write(&mut self, bytes: &[u8]) -> io::Result<bool> {
        match self {
            Self::Udp { socket, peer, .. } => match peer {
                Some(p) => socket.send_to(bytes, *p).await.map(|_| true),
                None => Ok(false),
            },
            Self::Tcp(s) => s.write_all(bytes).await.map(|()| true),
            Self::Serial(s) => s.write_all(bytes).await.map(|()| true),
        }
    }
}
