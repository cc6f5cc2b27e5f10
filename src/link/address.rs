//! Connection addresses in the forms MAVProxy, pymavlink and rust-mavlink
//! read (`mavlink-core` `ConnectionAddress::parse_address`, pymavlink
//! `mavutil.mavlink_connection`):
//!
//! | form | here | MAVProxy / pymavlink | rust-mavlink |
//! |---|---|---|---|
//! | `udpout:H:P` | send to H:P | same | same |
//! | `udpin:H:P`, `udp:H:P` | listen on H:P | `udp:` = listen | no `udp:` |
//! | `udpbcast:H:P` | broadcast to H:P until a peer answers, then to it | same | broadcast only |
//! | `tcpout:H:P`, `tcp:H:P` | connect to H:P | `tcp:` = connect | no `tcp:` |
//! | `tcpin:H:P` | listen on H:P, one client at a time | same | same |
//! | `serial:DEV:BAUD` | UART | a bare device path | same |
//!
//! Any other form is refused with this list ([`FORMS`]).

use std::fmt;

/// Where the link talks to the autopilot.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Address {
    /// `udpout:HOST:PORT`: send to HOST:PORT from an ephemeral port, receive
    /// the replies there. Sends even when nobody listens.
    UdpOut(String),
    /// `udpin:HOST:PORT`: bind HOST:PORT, reply to whoever sent last. Cannot
    /// send before the peer has sent something.
    UdpIn(String),
    /// `udpbcast:BCAST:PORT`: send to a broadcast address (SO_BROADCAST)
    /// until a peer answers, then to that peer only (pymavlink's lock-on).
    UdpBcast(String),
    /// `tcpout:HOST:PORT`: connect to a TCP server (SITL, a router);
    /// reconnects with back-off.
    TcpOut(String),
    /// `tcpin:HOST:PORT`: listen, serve one client at a time; after it hangs
    /// up, wait for the next.
    TcpIn(String),
    /// `serial:DEVICE:BAUD`: a UART; reopened with back-off when it fails or
    /// disappears.
    Serial {
        /// The serial device, e.g. `/dev/ttyAMA0`.
        device: String,
        /// Baud rate.
        baud: u32,
    },
}

impl fmt::Display for Address {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UdpOut(a) => write!(f, "udpout:{a}"),
            Self::UdpIn(a) => write!(f, "udpin:{a}"),
            Self::UdpBcast(a) => write!(f, "udpbcast:{a}"),
            Self::TcpOut(a) => write!(f, "tcpout:{a}"),
            Self::TcpIn(a) => write!(f, "tcpin:{a}"),
            Self::Serial { device, baud } => write!(f, "serial:{device}:{baud}"),
        }
    }
}

/// Checks `HOST:PORT` (the host may be a name or an IPv6 literal in brackets).
fn host_port(s: &str, whole: &str) -> Result<String, String> {
    let (host, port) = s
        .rsplit_once(':')
        .ok_or_else(|| format!("`{whole}`: expected HOST:PORT after the scheme"))?;
    if host.is_empty() {
        return Err(format!("`{whole}`: empty host"));
    }
    port.parse::<u16>()
        .map_err(|_| format!("`{whole}`: port `{port}` is not a number 0..65535"))?;
    Ok(s.to_string())
}

/// The accepted forms, for error messages and `--help`.
pub const FORMS: &str = "udpout:HOST:PORT (send), udpin:HOST:PORT or udp:HOST:PORT (listen), \
udpbcast:BCAST:PORT (broadcast, then the first peer that answers), tcpout:HOST:PORT or \
tcp:HOST:PORT (connect), tcpin:HOST:PORT (listen), serial:DEVICE:BAUD";

impl Address {
    /// Parses one of the [`FORMS`].
    pub fn parse(s: &str) -> Result<Self, String> {
        let s = s.trim();
        let (scheme, rest) = s
            .split_once(':')
            .ok_or_else(|| format!("`{s}`: expected one of {FORMS}"))?;
        match scheme {
            "udpout" => Ok(Self::UdpOut(host_port(rest, s)?)),
            // MAVProxy and pymavlink read `udp:` as listen.
            "udpin" | "udp" => Ok(Self::UdpIn(host_port(rest, s)?)),
            "udpbcast" => Ok(Self::UdpBcast(host_port(rest, s)?)),
            "tcpout" | "tcp" => Ok(Self::TcpOut(host_port(rest, s)?)),
            "tcpin" => Ok(Self::TcpIn(host_port(rest, s)?)),
            "serial" => {
                let (device, baud) = rest
                    .rsplit_once(':')
                    .ok_or_else(|| format!("`{s}`: expected serial:DEVICE:BAUD"))?;
                if device.is_empty() {
                    return Err(format!("`{s}`: empty serial device"));
                }
                let baud =
                    baud.parse::<u32>().ok().filter(|b| *b > 0).ok_or_else(|| {
                        format!("`{s}`: baud rate `{baud}` is not a positive number")
                    })?;
                Ok(Self::Serial {
                    device: device.to_string(),
                    baud,
                })
            }
            other => Err(format!(
                "`{s}`: unknown form `{other}:`; use one of {FORMS}"
            )),
        }
    }

    /// Stream transports (TCP, serial) are rebuilt when they fail; UDP only
    /// when its socket errors.
    pub fn is_stream(&self) -> bool {
        matches!(self, Self::TcpOut(_) | Self::TcpIn(_) | Self::Serial { .. })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_form() {
        assert_eq!(
            Address::parse("udpout:127.0.0.1:14550"),
            Ok(Address::UdpOut("127.0.0.1:14550".into()))
        );
        assert_eq!(
            Address::parse("udpin:0.0.0.0:14551"),
            Ok(Address::UdpIn("0.0.0.0:14551".into()))
        );
        assert_eq!(
            Address::parse("tcpout:localhost:5760"),
            Ok(Address::TcpOut("localhost:5760".into()))
        );
        // MAVProxy / pymavlink: `udp:` listens, `tcp:` connects.
        assert_eq!(
            Address::parse("udp:0.0.0.0:14550"),
            Ok(Address::UdpIn("0.0.0.0:14550".into()))
        );
        assert_eq!(
            Address::parse("tcp:127.0.0.1:5760"),
            Ok(Address::TcpOut("127.0.0.1:5760".into()))
        );
        assert_eq!(
            Address::parse("tcpin:0.0.0.0:5760").map(|a| a.to_string()),
            Ok("tcpin:0.0.0.0:5760".to_string())
        );
        assert_eq!(
            Address::parse("udpbcast:192.168.1.255:14550").map(|a| a.to_string()),
            Ok("udpbcast:192.168.1.255:14550".to_string())
        );
        assert_eq!(
            Address::parse("serial:/dev/ttyACM0:921600"),
            Ok(Address::Serial {
                device: "/dev/ttyACM0".into(),
                baud: 921600
            })
        );
        assert_eq!(
            Address::parse("serial:/dev/ttyACM0:57600").map(|a| a.to_string()),
            Ok("serial:/dev/ttyACM0:57600".to_string())
        );
    }

    #[test]
    fn rejects_bad_addresses_with_a_reason() {
        for bad in [
            "",
            "udpout",
            "udpout:127.0.0.1",
            "udpout:127.0.0.1:99999",
            "udpout::14550",
            "tcpin:127.0.0.1",
            "udpbcast::14550",
            "file:/tmp/x.tlog",
            "/dev/ttyACM0",
            "serial:/dev/ttyS0",
            "serial:/dev/ttyS0:fast",
            "serial::57600",
            "serial:/dev/ttyS0:0",
        ] {
            let e = Address::parse(bad).unwrap_err();
            assert!(e.contains('`'), "{bad}: {e}");
        }
        // An unknown form lists every form.
        let e = Address::parse("udpx:1.2.3.4:5").unwrap_err();
        for form in [
            "udpout:",
            "udpin:",
            "udp:",
            "udpbcast:",
            "tcpout:",
            "tcp:",
            "tcpin:",
            "serial:",
        ] {
            assert!(e.contains(form), "{e}");
        }
    }
}
