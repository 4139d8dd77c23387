package org.slf4j;

/** Stand-in for slf4j's Logger: the two calls IrisTK's Broker makes (pairplay test stub). */
public interface Logger {
    void info(String message);

    void error(String message);
}
