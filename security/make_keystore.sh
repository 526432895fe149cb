#!/usr/bin/env bash
# Makes a TEST SROS2-layout keystore for the suite with openssl only: an identity CA, a
# permissions CA, a signed domain governance and one enclave per node with its own identity
# and signed permissions. Only /qt_therapy/tablet_bridge may publish therapist commands (the
# therapist console too, where CONSOLE_MAY_COMMAND=1 asks for it); only
# /qt_therapy/engagement_classifier may publish engagement.
# The CA keys are unencrypted and kept in OUT_DIR/private: fine for tests, not for a clinic.
#   usage: security/make_keystore.sh OUT_DIR [DOMAIN_MAX]
#   env DATA_PROTECTION_KIND=NONE|SIGN|ENCRYPT (default NONE, see the governance below)
#   env CONSOLE_MAY_COMMAND=1 lets /qt_therapy/therapist_console publish therapist commands
#     (default 0: the therapist tablet, through the bridge, is the only way to command)
set -euo pipefail
[ $# -ge 1 ] || { echo "usage: make_keystore.sh OUT_DIR [DOMAIN_MAX]" >&2; exit 2; }
out=$1
domain_max=${2:-232}
data_protection=${DATA_PROTECTION_KIND:-NONE}
console_may_command=${CONSOLE_MAY_COMMAND:-0}
case $data_protection in NONE | SIGN | ENCRYPT) ;; *)
  echo "make_keystore.sh: DATA_PROTECTION_KIND must be NONE, SIGN or ENCRYPT" >&2; exit 2 ;;
esac
command -v openssl >/dev/null || { echo "make_keystore.sh: openssl not found" >&2; exit 1; }
mkdir -p "$out/public" "$out/private" "$out/enclaves"
out=$(cd "$out" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# Nodes of the suite, as SROS2 enclave paths.
enclaves=(
  /qt_therapy/tablet_bridge
  /qt_therapy/therapist_console
  /qt_therapy/game_manager
  /qt_therapy/engagement_classifier
  /qt_therapy/behaviour_policy
  /qt_therapy/user_model
  /qt_therapy/simulated_child
  /qt_therapy/bag_recorder
  /qt_therapy/bag_player
)
# The DDS names (ROS 2 adds rt/) of the topics whose writers are restricted
# (msgs/src/topics.rs: THERAPIST_COMMAND, ENGAGEMENT_ESTIMATE, EXPECTED_ENGAGEMENT).
command_topic=rt/qt_therapy/therapist/command
engagement_topics=(rt/qt_therapy/engagement/estimate rt/qt_therapy/engagement/expected)

# SROS2 uses NIST P-256 keys and SHA-256 everywhere.
openssl ecparam -name prime256v1 -out "$tmp/ec.pem"

make_ca() { # NAME CN
  openssl req -x509 -newkey "param:$tmp/ec.pem" -nodes -sha256 -days 3650 \
    -keyout "$out/private/$1.key.pem" -out "$out/public/$1.cert.pem" \
    -subj "/CN=$2" 2>/dev/null
}
make_ca identity_ca qt_therapy_identity_ca
make_ca permissions_ca qt_therapy_permissions_ca

sign() { # IN OUT: S/MIME signature by the permissions CA, as SROS2 does
  openssl smime -sign -text -in "$1" -out "$2" \
    -signer "$out/public/permissions_ca.cert.pem" -inkey "$out/private/permissions_ca.key.pem"
}

# Governance: SROS2's default (no unauthenticated participants, discovery and liveliness
# encrypted, RTPS messages signed, read and write access control on every topic, submessages
# encrypted) with one change: data_protection_kind NONE instead of ENCRYPT. RustDDS 0.15.1
# pads an encoded payload to 4 bytes on the wire and its decoder then reads the padding as
# part of the crypto footer, so every sample whose encoded length is not a multiple of 4
# fails to decrypt (ring "Unspecified"; README, DDS Security, and the ignored test
# rustdds_payload_encryption_loses_samples_of_unaligned_length). With
# metadata_protection_kind ENCRYPT the whole DATA submessage, payload included, is still
# encrypted and authenticated on the wire; what is lost is only end-to-end payload
# protection through a relay, which this suite does not use.
cat >"$out/enclaves/governance.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
  xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains>
        <id_range><min>0</min><max>$domain_max</max></id_range>
      </domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>$data_protection</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML
sign "$out/enclaves/governance.xml" "$out/enclaves/governance.p7s"

topics_xml() { for t in "$@"; do printf '            <topic>%s</topic>\n' "$t"; done; }

for enclave in "${enclaves[@]}"; do
  dir="$out/enclaves${enclave}"
  mkdir -p "$dir"
  # Identity: the subject is the enclave path, as in SROS2.
  openssl req -newkey "param:$tmp/ec.pem" -nodes -sha256 -keyout "$dir/key.pem" \
    -out "$tmp/req.pem" -subj "/CN=${enclave//\//\\/}" 2>/dev/null
  openssl x509 -req -sha256 -days 3650 -in "$tmp/req.pem" \
    -CA "$out/public/identity_ca.cert.pem" -CAkey "$out/private/identity_ca.key.pem" \
    -set_serial "0x$(openssl rand -hex 8)" -out "$dir/cert.pem" 2>/dev/null
  cp "$out/public/identity_ca.cert.pem" "$out/public/permissions_ca.cert.pem" \
    "$out/enclaves/governance.p7s" "$dir/"

  # Restricted topics this enclave may NOT publish. Rules are read in order, first match wins,
  # so the deny rule comes before the general allow rule.
  denied=()
  case $enclave in
    /qt_therapy/tablet_bridge) denied=("${engagement_topics[@]}") ;;
    /qt_therapy/therapist_console)
      denied=("${engagement_topics[@]}")
      [ "$console_may_command" = 1 ] || denied+=("$command_topic") ;;
    /qt_therapy/engagement_classifier) denied=("$command_topic") ;;
    *) denied=("$command_topic" "${engagement_topics[@]}") ;;
  esac
  {
    cat <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
  xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$enclave">
      <subject_name>CN=$enclave</subject_name>
      <validity>
        <not_before>2024-01-01T00:00:00</not_before>
        <not_after>2099-01-01T00:00:00</not_after>
      </validity>
      <deny_rule>
        <domains><id_range><min>0</min><max>$domain_max</max></id_range></domains>
        <publish>
          <topics>
XML
    topics_xml "${denied[@]}"
    cat <<XML
          </topics>
        </publish>
      </deny_rule>
      <allow_rule>
        <domains><id_range><min>0</min><max>$domain_max</max></id_range></domains>
        <publish>
          <topics>
            <topic>*</topic>
          </topics>
        </publish>
        <subscribe>
          <topics>
            <topic>*</topic>
          </topics>
        </subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
XML
  } >"$dir/permissions.xml"
  sign "$dir/permissions.xml" "$dir/permissions.p7s"
done
echo "keystore in $out: enclaves ${enclaves[*]}"
