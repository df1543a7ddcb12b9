//! TLS for MQTT clients that reach the Pi's broker from another machine (the pit laptop's
//! dashboard, a Pi service publishing to a remote broker). The server's certificate is
//! checked against the PEM file the team gives, and only that: the team's own CA, or the Pi's
//! certificate itself (pinned). Never the system's store: no public CA signs a pit network's
//! addresses, and trusting one would let anyone with a public certificate in.

use rustls::pki_types::CertificateDer;
use rustls::pki_types::pem::PemObject;
use std::error::Error as StdError;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Why the trusted certificates could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum TlsSetupError {
    #[error("reading the trusted certificates {path}: {source}")]
    Read {
        path: PathBuf,
        source: rustls::pki_types::pem::Error,
    },
    #[error("{path} holds no PEM certificate")]
    Empty { path: PathBuf },
    #[error("{path}: a certificate that cannot be trusted as an anchor: {source}")]
    Anchor {
        path: PathBuf,
        source: rustls::Error,
    },
    #[error("TLS protocol versions: {0}")]
    Versions(rustls::Error),
}

/// A client configuration that trusts exactly the certificates in the PEM file `trusted`
/// (TLS 1.2 and 1.3, ring).
pub fn client_config(trusted: &Path) -> Result<Arc<rustls::ClientConfig>, TlsSetupError> {
    let certificates = CertificateDer::pem_file_iter(trusted)
        .and_then(|certs| certs.collect::<Result<Vec<_>, _>>())
        .map_err(|source| TlsSetupError::Read {
            path: trusted.to_path_buf(),
            source,
        })?;
    if certificates.is_empty() {
        return Err(TlsSetupError::Empty {
            path: trusted.to_path_buf(),
        });
    }
    let mut roots = rustls::RootCertStore::empty();
    for certificate in certificates {
        roots
            .add(certificate)
            .map_err(|source| TlsSetupError::Anchor {
                path: trusted.to_path_buf(),
                source,
            })?;
    }
    let config = rustls::ClientConfig::builder_with_provider(Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .map_err(TlsSetupError::Versions)?
    .with_root_certificates(roots)
    .with_no_client_auth();
    Ok(Arc::new(config))
}

/// The TLS failure somewhere in `error`'s chain (rustls reports through `io::Error`s), if
/// any.
pub fn tls_failure<'e>(error: &'e (dyn StdError + 'static)) -> Option<&'e rustls::Error> {
    let mut current: Option<&(dyn StdError + 'static)> = Some(error);
    while let Some(error) = current {
        if let Some(tls) = error.downcast_ref::<rustls::Error>() {
            return Some(tls);
        }
        if let Some(tls) = error
            .downcast_ref::<std::io::Error>()
            .and_then(|io| io.get_ref())
            .and_then(|inner| inner.downcast_ref::<rustls::Error>())
        {
            return Some(tls);
        }
        current = error.source();
    }
    None
}

/// A TLS failure in words a pit crew can act on; `host` is the name the client asked for and
/// `trusted` the variable or setting that names the trusted file.
pub fn explain(failure: &rustls::Error, host: &str, trusted: &str) -> String {
    use rustls::CertificateError as C;
    match failure {
        rustls::Error::InvalidCertificate(C::UnknownIssuer | C::BadSignature) => format!(
            "the broker's certificate is not one {trusted} trusts: a certificate of another \
             CA, or a Pi whose certificate was remade (install the team's CA or the Pi's \
             current certificate)"
        ),
        rustls::Error::InvalidCertificate(
            C::NotValidForName | C::NotValidForNameContext { .. },
        ) => {
            format!(
                "the broker's certificate is not made out for {host}: connect by the name or \
                 address it names, or remake it with {host} in its subjectAltName"
            )
        }
        rustls::Error::InvalidCertificate(
            C::Expired | C::ExpiredContext { .. } | C::NotValidYet | C::NotValidYetContext { .. },
        ) => "the broker's certificate is outside its validity dates (is this computer's clock \
              right?)"
            .into(),
        rustls::Error::InvalidMessage(_) => {
            "the listener does not speak TLS: the pit listener does, the Pi's loopback \
             listener does not (check the port)"
                .into()
        }
        other => format!("TLS failed: {other}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_without_certificates_is_refused_with_its_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ca.pem");
        std::fs::write(&path, "not a certificate\n").unwrap();
        let error = client_config(&path).unwrap_err();
        assert!(matches!(error, TlsSetupError::Empty { .. }), "{error}");
        assert!(error.to_string().contains("ca.pem"));
        let missing = client_config(&dir.path().join("missing.pem")).unwrap_err();
        assert!(matches!(missing, TlsSetupError::Read { .. }), "{missing}");
    }

    #[test]
    fn a_rustls_failure_is_found_inside_an_io_error() {
        let io = std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            rustls::Error::InvalidCertificate(rustls::CertificateError::UnknownIssuer),
        );
        let found = tls_failure(&io).expect("found");
        assert!(explain(found, "pi.local", "AER_MQTT_TLS_CA").contains("AER_MQTT_TLS_CA"));
        let plain = std::io::Error::other("refused");
        assert!(tls_failure(&plain).is_none());
    }
}
