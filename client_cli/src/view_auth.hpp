// The login of `facescan view --tls` on CivetWeb: the login page, POST /login and /logout, and the session cookie
// every other request needs (client/view_logins.hpp keeps the logins and sessions). Internal to the viewer.
//
// The cookie is __Host-facescan_session (the __Host- prefix: only over HTTPS, for this host, path /), HttpOnly
// (no script reads it), Secure and SameSite=Strict (never sent with a request another site starts).
#pragma once

#include <functional>
#include <optional>
#include <string>

#include "client/view_logins.hpp"

struct mg_connection;

namespace facescan::client::detail {

inline constexpr const char* kSessionCookie = "__Host-facescan_session";

// Seconds on a steady clock (the sessions' time).
double loginClockS();

// GET/HEAD /login: the page. POST /login: a form (user, password); 303 to / with the cookie, 401 with the page
// again, or 429 with Retry-After while the brake is on. POST /logout: ends the session, 303 to /login.
// `address` is the browser's (the brake on wrong passwords counts per address).
// `audit(user, outcome)` records each attempt.
int handleLogin(mg_connection* conn, LoginBook& logins, double max_age_s, const std::string& address,
                const std::function<void(const std::string&, const std::string&)>& audit);
int handleLogout(mg_connection* conn, LoginBook& logins);

// The user of the request's session cookie, or nullopt.
std::optional<std::string> sessionUser(const mg_connection* conn, LoginBook& logins);

// Without a session: the page (/ and /index.html) redirects to /login (303); everything else is 401 with a JSON
// error and nothing of the scans.
int refuseWithoutLogin(mg_connection* conn, const std::string& uri);

}  // namespace facescan::client::detail
